#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `mocomp head inspect`: FreeSurfer's fsaverage head, written by trimesh as STL, read, mended,
//! drawn and written out as PLY, which reads back the same; a missing unit and a broken file
//! are bad input (exit 2) with a message naming the file.

mod common;
use common::{assert_success, mocomp};
use mocomp_testkit::{PythonPeer, TempDir};
use serde_json::{Value, json};

fn inspect_json(args: &[&str]) -> Value {
    let out = mocomp(args);
    assert_success(&out);
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn a_scalp_is_inspected_drawn_and_written_back() {
    let mut peer = PythonPeer::start(
        "head_peer.py",
        "mne, nibabel, trimesh",
        "mne 1.13.2, nibabel 5.4.2, trimesh 5.2.0",
    );
    let dir = TempDir::new("mocomp-head");
    let stl = dir.path("head.stl");
    let a = peer.request(&json!({"op": "write", "format": "stl", "path": stl, "scale": 1000.0}));
    assert!(a.get("error").is_none(), "{a}");
    let (png, ply) = (dir.path("views.png"), dir.path("mended.ply"));
    let j = inspect_json(&[
        "head",
        "inspect",
        &stl,
        "--units",
        "mm",
        "--json",
        "--png",
        &png,
        "--write-mesh",
        &ply,
    ]);
    assert_eq!(
        (j["vertices"].as_u64(), j["faces"].as_u64()),
        (Some(2033), Some(4062))
    );
    assert_eq!(j["closed"], true);
    assert_eq!(j["read"]["vertices"].as_u64(), Some(3 * 4062));
    // fsaverage's scalp: x −83…86, y −123…98, z −164…99 mm (MNE's own figures).
    let b = &j["bounds_m"];
    for (k, (lo, hi)) in [(-0.083, 0.086), (-0.123, 0.098), (-0.164, 0.099)]
        .iter()
        .enumerate()
    {
        assert!((b[0][k].as_f64().unwrap() - lo).abs() < 1e-3, "{b}");
        assert!((b[1][k].as_f64().unwrap() - hi).abs() < 1e-3, "{b}");
    }
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (1200, 400));
    // The head fills the middle of each panel; the corners are background.
    for panel in 0..3 {
        assert_ne!(img.get_pixel(panel * 400 + 200, 200).0, [255, 255, 255]);
        assert_eq!(img.get_pixel(panel * 400 + 3, 3).0, [255, 255, 255]);
    }
    let back = inspect_json(&["head", "inspect", &ply, "--units", "mm", "--json"]);
    assert_eq!(back["vertices"], j["vertices"]);
    assert_eq!(back["faces"], j["faces"]);
    assert_eq!(back["repairs"]["merged_vertices"], 0);
    for k in 0..2 {
        for c in 0..3 {
            let (x, y) = (
                back["bounds_m"][k][c].as_f64().unwrap(),
                b[k][c].as_f64().unwrap(),
            );
            assert!((x - y).abs() < 1e-9);
        }
    }
    // Text: what was read and what was mended, in words.
    let out = mocomp(&["head", "inspect", &stl, "--units", "mm"]);
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("2033 vertices, 4062 triangles, closed as read"),
        "{text}"
    );
    assert!(text.contains("10153 duplicate vertices merged"), "{text}");
}

#[test]
fn a_missing_unit_or_a_broken_file_is_bad_input() {
    let dir = TempDir::new("mocomp-head-bad");
    let stl = dir.path("cut.stl");
    let mut bytes = vec![0u8; 80];
    bytes.extend_from_slice(&1000u32.to_le_bytes());
    bytes.extend_from_slice(&[0u8; 120]);
    std::fs::write(&stl, &bytes).unwrap();
    let out = mocomp(&["head", "inspect", &stl, "--units", "mm"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("cut.stl: it declares 1000 triangles"), "{err}");
    let out = mocomp(&["head", "inspect", &stl]);
    assert_eq!(out.status.code(), Some(2));
    let out = mocomp(&["head", "inspect", &dir.path("absent.ply"), "--units", "mm"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8(out.stderr)
            .unwrap()
            .contains("absent.ply")
    );
    let out = mocomp(&["head", "inspect", &stl, "--units", "cm"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8(out.stderr).unwrap().contains("--units"));
}

/// Colin27, the real T1 in mocomp-mri's test data (SOURCE.md beside it).
fn colin27() -> String {
    mocomp_testkit::workspace_root()
        .join("crates/mocomp-mri/tests/data/colin27/colin27_ch2_1mm.nii.gz")
        .display()
        .to_string()
}

#[test]
fn a_t1_mri_is_segmented_to_a_scalp_of_the_size_asked_and_written_out() {
    let dir = TempDir::new("mocomp-head-mri");
    let ply = dir.path("scalp.ply");
    let t1 = colin27();
    let j = inspect_json(&[
        "head",
        "inspect",
        &t1,
        "--units",
        "mm",
        "--max-triangles",
        "20000",
        "--json",
        "--write-mesh",
        &ply,
    ]);
    assert_eq!(j["format"], "nifti");
    assert_eq!(j["closed"], true);
    let faces = j["faces"].as_u64().unwrap();
    assert!(faces <= 20_000 && faces > 19_000, "{j}");
    let g = &j["segmentation"];
    assert_eq!(g["threshold_from"], "otsu");
    assert_eq!(g["dims"], json!([181, 217, 181]));
    // The MNI box cuts Colin27 at the neck, both ears and the brow: the inspection says so.
    let sides: Vec<&str> = g["cut_by_scan"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["side"].as_str().unwrap())
        .collect();
    assert_eq!(sides, ["left", "right", "anterior", "inferior"], "{g}");
    // Each with the patch of the box's face it covers: the left one in the plane x = -90.5 mm,
    // facing out of the box.
    let left = &g["cut_by_scan"][0];
    assert_eq!(left["outward"], json!([-1.0, 0.0, 0.0]), "{left}");
    assert!(
        (left["centre_m"][0].as_f64().unwrap() + 0.0905).abs() < 1e-9,
        "{left}"
    );
    assert!(left["half_m"][0].as_f64().unwrap() > 0.01, "{left}");
    // The surface written out reads back as the same closed surface.
    let back = inspect_json(&["head", "inspect", &ply, "--units", "mm", "--json"]);
    assert_eq!(back["faces"].as_u64(), Some(faces));
    assert_eq!(back["closed"], true);
    assert_eq!(back["repairs"]["merged_vertices"], 0);
}

#[test]
fn a_t1_without_a_unit_or_without_a_head_is_bad_input() {
    let t1 = colin27();
    for (args, says) in [
        (vec![], "xyzt_units"),
        (vec!["--units", "mm", "--threshold", "255"], "no head"),
        (
            vec!["--units", "mm", "--max-triangles", "10"],
            "--max-triangles",
        ),
    ] {
        let mut all = vec!["head", "inspect", t1.as_str()];
        all.extend(args.iter().copied());
        let out = mocomp(&all);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8(out.stderr).unwrap();
        assert!(err.contains(says), "{args:?}: {err}");
    }
}
