#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `mocomp placement check|search` and a run that never reaches its goal: a head placed past
//! the arm's reach is said to be unreachable (and why) before anything moves, the search finds
//! a place that reaches, the loop reaches the goal there, and a run at the first place exits 1
//! naming the rule that held it and what to do.

mod common;
use common::{assert_success, example_changed, mocomp, run_args};
use mocomp_testkit::TempDir;

const REST: &str = "# initial_joints_rad = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0]";
const PLACE: &str = "base_from_head = [0.30, -0.12, -0.02, 0.0, 0.0, 0.3]";

/// The example with the head at `place` and the arm resting at its working pose (`rest`),
/// else where the simulated world starts it (15 cm out on the goal's axis).
fn placed(dir: &TempDir, host: &str, place: &str, rest: bool) -> String {
    let at = format!("base_from_head = {place}");
    let mut changes = vec![(PLACE, at.as_str())];
    if rest {
        changes.push((
            REST,
            "initial_joints_rad = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0]",
        ));
    }
    example_changed(dir, host, &changes)
}

#[test]
fn a_head_out_of_reach_is_said_searched_for_and_a_run_there_fails_naming_the_rule() {
    let dir = TempDir::new("mocomp-placement");
    // 32 cm further from the base than the example's place: past a UR3e's reach.
    let far = placed(
        &dir,
        "127.0.0.241",
        "[0.62, -0.12, -0.02, 0.0, 0.0, 0.3]",
        true,
    );
    let out = mocomp(&["placement", "check", "--config", &far]);
    let text = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{text}{err}");
    assert!(text.starts_with("goal: NOT REACHABLE: "), "{text}");
    assert!(text.contains("move the patient or the robot"), "{text}");
    assert!(err.contains("placement search"), "{err}");

    // The search over a line toward the base finds a place, printed as the key to set.
    let out = mocomp(&[
        "placement",
        "search",
        "--config",
        &far,
        "--region-mm",
        "300,0,0",
        "--step-mm",
        "100",
        "--yaw-deg",
        "0",
        "--json",
        "--png",
        &dir.path("placement.png"),
    ]);
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["tried"], 7, "{j}");
    // Drawn: both heads, the found one green (mocomp_report::placement's colour), the refused
    // target at the configured place red.
    let img = image::open(dir.path("placement.png")).unwrap().to_rgb8();
    let near = |c: [u8; 3]| {
        img.pixels()
            .filter(|p| (0..3).all(|k| (i32::from(p[k]) - i32::from(c[k])).abs() < 30))
            .count()
    };
    assert!(near([27, 138, 58]) > 300, "green: {}", near([27, 138, 58]));
    assert!(near([198, 40, 40]) > 50, "red: {}", near([198, 40, 40]));
    assert!(j["reaching"].as_u64().unwrap() >= 1, "{j}");
    assert_eq!(j["targets"][0]["reachable"], true, "{j}");
    let moved = j["moved_mm"][0].as_f64().unwrap();
    assert!(moved < -50.0, "toward the base: {j}");
    let place: Vec<f64> = j["base_from_head"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    assert!((place[0] - (0.62 + moved / 1e3)).abs() < 1e-9, "{j}");

    // There, `check` agrees and the loop reaches its goal (from the simulated world's start
    // near it: the way from the working pose, a half turn of the base joint, is checked above).
    let near_dir = TempDir::new("mocomp-placement-near");
    let near = placed(&near_dir, "127.0.0.242", &format!("{place:?}"), false);
    assert_success(&mocomp(&["placement", "check", "--config", &near]));
    let out = mocomp(&run_args(&near, "8", &[]));
    assert_success(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["tracking_percent"].as_f64().unwrap() > 0.0, "{v}");
    assert!(v["not_reached"].is_null(), "{v}");

    // At the first place the run is held from its start and fails, saying why and what to do.
    let out = mocomp(&run_args(&far, "3", &[]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("never reached its goal") && err.contains("move the patient or the robot"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["tracking_percent"].as_f64(), Some(0.0), "{v}");
    assert!(
        v["not_reached"]["held_percent"].as_u64().unwrap() > 50,
        "{v}"
    );
}

#[test]
fn targets_add_says_when_the_arm_cannot_reach_the_new_target() {
    // The fsaverage head of the registration tests, at the example's place: its crown reaches,
    // the inion does not (the arm comes from above the head's front).
    let dir = TempDir::new("mocomp-placement-add");
    let (cfg, _) = common::fsaverage_config(&dir, "");
    let targets = dir.path("t.toml");
    let add = |name: &str, eeg: &str| {
        let out = mocomp(&[
            "targets", "--file", &targets, "add", name, "--config", &cfg, "--eeg", eeg,
        ]);
        assert_success(&out);
        String::from_utf8_lossy(&out.stdout).to_string()
    };
    let cz = add("cz", "Cz");
    assert!(
        cz.contains("at the configured placement: cz: reachable"),
        "{cz}"
    );
    assert!(!cz.contains("NOT REACHABLE"), "{cz}");
    let oz = add("oz", "Oz");
    assert!(oz.contains("oz: NOT REACHABLE"), "{oz}");
    assert!(oz.contains("placement search --config"), "{oz}");
}
