#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `mocomp targets`: a session's named targets in their file; a grid around one on the
//! configuration's head model; bad names and grids refused with exit 2, the file untouched.

mod common;
use common::{assert_success, mocomp};
use mocomp_testkit::{TempDir, workspace_root};

fn list(file: &str) -> Vec<serde_json::Value> {
    let out = mocomp(&["targets", "--file", file, "list", "--json"]);
    assert_success(&out);
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn a_grid_around_a_target_is_kept_in_the_file_and_targets_can_be_deleted() {
    let dir = TempDir::new("mocomp-targets");
    let file = dir.path("session.toml");
    // The example's goal as the hotspot: on top of the head, 3 mm off, +z into it.
    std::fs::write(
        &file,
        "[[target]]\nname = \"hotspot\"\nhead_from_coil = [0.0, 0.0, 0.113, 3.141592653589793, 0.0, 0.0]\nnote = \"APB\"\n",
    )
    .unwrap();
    let config = workspace_root().join("examples/run-sim.toml");
    let out = mocomp(&[
        "targets",
        "--file",
        &file,
        "grid",
        "hotspot",
        "--config",
        config.to_str().unwrap(),
        "--spacing-mm",
        "8",
        "--rows",
        "3",
        "--cols",
        "3",
    ]);
    assert_success(&out);
    let all = list(&file);
    assert_eq!(all.len(), 10);
    assert_eq!(all[0]["name"], "hotspot");
    assert_eq!(all[0]["note"], "APB");
    // The grid's centre is the hotspot, neighbours 8 mm apart, each axis into the head.
    let pos = |name: &str| -> [f64; 3] {
        let t = all.iter().find(|t| t["name"] == name).unwrap();
        std::array::from_fn(|i| t["position_mm"][i].as_f64().unwrap())
    };
    let d = |a: [f64; 3], b: [f64; 3]| {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    };
    assert!(d(pos("hotspot-r1c1"), pos("hotspot")) < 1e-6);
    // The coils sit 3 mm off the surface, so their centres are a little further apart than the
    // surface points.
    let step = d(pos("hotspot-r1c0"), pos("hotspot-r1c1"));
    assert!((step - 8.0).abs() < 0.5, "{step} mm");
    for t in &all {
        assert!(t["axis"][2].as_f64().unwrap() < -0.9, "{t}");
        assert!(!t["taught_at"].as_str().unwrap().is_empty() || t["name"] == "hotspot");
    }
    // Deleting one keeps the rest.
    let out = mocomp(&["targets", "--file", &file, "delete", "hotspot-r0c0"]);
    assert_success(&out);
    assert_eq!(list(&file).len(), 9);
}

#[test]
fn an_unknown_target_or_a_bad_grid_is_refused_and_the_file_left_as_it_was() {
    let dir = TempDir::new("mocomp-targets-bad");
    let file = dir.path("session.toml");
    let text = "[[target]]\nname = \"a\"\nhead_from_coil = [0.0, 0.0, 0.113, 3.141592653589793, 0.0, 0.0]\n";
    std::fs::write(&file, text).unwrap();
    let config = workspace_root().join("examples/run-sim.toml");
    let out = mocomp(&["targets", "--file", &file, "delete", "b"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no target \"b\"") && err.contains("has: a"),
        "{err}"
    );
    let out = mocomp(&[
        "targets",
        "--file",
        &file,
        "grid",
        "a",
        "--config",
        config.to_str().unwrap(),
        "--rows",
        "0",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("rows = 0"));
    assert_eq!(std::fs::read_to_string(&file).unwrap(), text);
    // A broken file is named.
    std::fs::write(&file, "[[target]]\nname = 3\n").unwrap();
    let out = mocomp(&["targets", "--file", &file, "list"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("session.toml"));
}
