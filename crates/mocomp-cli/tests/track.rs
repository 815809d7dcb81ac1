//! `mocomp track` and `mocomp track render`: rendered frames tracked against their ground truth;
//! bad input (sizes, 8-bit images, missing files, empty directories, small geometries) gives one
//! clear line and exit 2; frames without markers are reported, not fatal.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::{assert_success, mocomp};

use mocomp_geom::nalgebra::Matrix4;
use mocomp_geom::{iso_from_matrix_mm, rotation_error, translation_error};
use mocomp_testkit::TempDir;
use mocomp_vision::codec::{encode_gray16_png, encode_rgb_png};

const GEOMETRY: &str =
    "name = \"8700449\"\npoints_mm = [[0,0,0],[0,47.38,28.99],[0,0,89.1],[0,-35.36,35.36]]\n";

fn pose(v: &serde_json::Value) -> mocomp_geom::nalgebra::Isometry3<f64> {
    let m = Matrix4::from_fn(|r, c| v[r][c].as_f64().unwrap());
    iso_from_matrix_mm(&m, 1e-6).unwrap()
}

#[test]
fn rendered_frames_are_tracked_to_their_truth() {
    let d = TempDir::new("track-ok");
    std::fs::write(d.path("g.toml"), GEOMETRY).unwrap();
    let out = mocomp(&[
        "track",
        "render",
        "--out",
        &d.path("frames"),
        "--geometry",
        &d.path("g.toml"),
        "--count",
        "12",
        "--distractors",
    ]);
    assert_success(&out);
    let out = mocomp(&[
        "track",
        "--frames",
        &d.path("frames"),
        "--intrinsics",
        &d.path("frames/intrinsics.toml"),
        "--geometry",
        &d.path("g.toml"),
        "--overlay",
        &d.path("overlay"),
        "--json",
    ]);
    assert_success(&out);
    let tracked = String::from_utf8(out.stdout).unwrap();
    let truth = std::fs::read_to_string(d.path("frames/truth.jsonl")).unwrap();
    let mut found = 0;
    for (a, b) in tracked.lines().zip(truth.lines()) {
        let a: serde_json::Value = serde_json::from_str(a).unwrap();
        let b: serde_json::Value = serde_json::from_str(b).unwrap();
        assert_eq!(a["frame"], b["frame"]);
        assert!(a["blobs"].as_u64().unwrap() >= 4);
        if a["found"] == true {
            found += 1;
            let (pa, pb) = (
                pose(&a["tracker_from_marker"]),
                pose(&b["tracker_from_marker"]),
            );
            assert!(translation_error(&pa, &pb) < 0.003, "{}", a["frame"]);
            assert!(rotation_error(&pa, &pb).to_degrees() < 2.0);
            assert!(a["fre_mm"].as_f64().unwrap() < 2.0);
        } else {
            assert!(a["reason"].as_str().unwrap().len() > 5);
        }
    }
    assert!(found >= 10, "found {found} of 12");
    assert!(std::path::Path::new(&d.path("overlay/0000_overlay.png")).exists());
}

fn expect_error(args: &[&str], needles: &[&str]) {
    let out = mocomp(args);
    assert_eq!(
        out.status.code(),
        Some(2),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err:?}");
    for n in needles {
        assert!(err.contains(n), "{err:?} should contain {n:?}");
    }
}

#[test]
fn bad_input_is_named() {
    let d = TempDir::new("track-bad");
    std::fs::write(d.path("g.toml"), GEOMETRY).unwrap();
    std::fs::write(
        d.path("i.toml"),
        "width = 4\nheight = 3\nfx = 3\nfy = 3\ncx = 2\ncy = 1.5\n",
    )
    .unwrap();
    let track = |frames: &str| {
        vec![
            "track".to_string(),
            "--frames".into(),
            d.path(frames),
            "--intrinsics".into(),
            d.path("i.toml"),
            "--geometry".into(),
            d.path("g.toml"),
        ]
    };
    let run = |frames: &str, needles: &[&str]| {
        let a = track(frames);
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        expect_error(&refs, needles);
    };
    // IR and depth of different sizes.
    std::fs::create_dir_all(d.path("sizes")).unwrap();
    std::fs::write(
        d.path("sizes/a_ir.png"),
        encode_gray16_png(4, 3, &[0; 12], "a").unwrap(),
    )
    .unwrap();
    std::fs::write(
        d.path("sizes/a_depth.png"),
        encode_gray16_png(5, 3, &[0; 15], "a").unwrap(),
    )
    .unwrap();
    run("sizes", &["a_depth.png", "5×3", "4×3"]);
    // An 8-bit image where 16-bit is expected.
    std::fs::create_dir_all(d.path("eight")).unwrap();
    std::fs::write(
        d.path("eight/a_ir.png"),
        encode_rgb_png(4, 3, &[0; 36], "a").unwrap(),
    )
    .unwrap();
    std::fs::write(
        d.path("eight/a_depth.png"),
        encode_gray16_png(4, 3, &[0; 12], "a").unwrap(),
    )
    .unwrap();
    run("eight", &["a_ir.png", "16-bit"]);
    // A missing depth image, and an empty directory.
    std::fs::create_dir_all(d.path("nodepth")).unwrap();
    std::fs::write(
        d.path("nodepth/a_ir.png"),
        encode_gray16_png(4, 3, &[0; 12], "a").unwrap(),
    )
    .unwrap();
    run("nodepth", &["a_ir.png", "no matching depth"]);
    std::fs::create_dir_all(d.path("empty")).unwrap();
    run("empty", &["no <name>_ir.png"]);
    // A frame not the size of the intrinsics.
    std::fs::create_dir_all(d.path("other")).unwrap();
    std::fs::write(
        d.path("other/a_ir.png"),
        encode_gray16_png(2, 2, &[0; 4], "a").unwrap(),
    )
    .unwrap();
    std::fs::write(
        d.path("other/a_depth.png"),
        encode_gray16_png(2, 2, &[0; 4], "a").unwrap(),
    )
    .unwrap();
    run("other", &["a_ir.png", "2×2", "4×3"]);
    // A geometry with fewer than 3 points.
    std::fs::write(d.path("two.toml"), "points_mm = [[0,0,0],[50,0,0]]\n").unwrap();
    expect_error(
        &[
            "track",
            "--frames",
            &d.path("empty"),
            "--intrinsics",
            &d.path("i.toml"),
            "--geometry",
            &d.path("two.toml"),
        ],
        &["two.toml", "at least 3"],
    );
}

#[test]
fn frames_without_markers_are_reported_and_the_run_goes_on() {
    let d = TempDir::new("track-blank");
    std::fs::write(d.path("g.toml"), GEOMETRY).unwrap();
    std::fs::write(
        d.path("i.toml"),
        "width = 8\nheight = 6\nfx = 6\nfy = 6\ncx = 4\ncy = 3\n",
    )
    .unwrap();
    std::fs::create_dir_all(d.path("f")).unwrap();
    for name in ["a", "b"] {
        std::fs::write(
            d.path(&format!("f/{name}_ir.png")),
            encode_gray16_png(8, 6, &[100; 48], name).unwrap(),
        )
        .unwrap();
        std::fs::write(
            d.path(&format!("f/{name}_depth.png")),
            encode_gray16_png(8, 6, &[1000; 48], name).unwrap(),
        )
        .unwrap();
    }
    let out = mocomp(&[
        "track",
        "--frames",
        &d.path("f"),
        "--intrinsics",
        &d.path("i.toml"),
        "--geometry",
        &d.path("g.toml"),
        "--json",
    ]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(text.lines().count(), 2);
    for l in text.lines() {
        let v: serde_json::Value = serde_json::from_str(l).unwrap();
        assert_eq!(v["found"], false);
        assert!(v["reason"].as_str().unwrap().contains("candidate"));
    }
}
