#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `mocomp teach-goal` and `mocomp calibrate collect` on the simulated robot and tracker (real
//! RTDE and OpenIGTLink on loopback): the taught goal is where the coil is, written into the
//! configuration with its comments kept; a goal that would be unsafe is refused; the collected
//! calibration finds the simulation's true tracker placement, and `run` uses the file it wrote.

mod common;
use common::{assert_success, mocomp};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_geom::{iso_from_ur_pose, rotation_error, translation_error};
use mocomp_testkit::{TempDir, workspace_root};

fn example(host: &str) -> String {
    let text = std::fs::read_to_string(workspace_root().join("examples/run-sim.toml")).unwrap();
    assert!(text.contains("host = \"127.0.0.2\""));
    text.replace("host = \"127.0.0.2\"", &format!("host = \"{host}\""))
}

fn goal_of(text: &str) -> Isometry3<f64> {
    let v: toml::Value = toml::from_str(text).unwrap();
    let g: Vec<f64> = v["goal"]["head_from_coil"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_float().unwrap())
        .collect();
    iso_from_ur_pose(&[g[0], g[1], g[2], g[3], g[4], g[5]]).unwrap()
}

#[test]
fn teach_goal_stores_where_the_coil_is_relative_to_the_head() {
    let dir = TempDir::new("mocomp-teach");
    // The goal is taught with the head still: the example's head starts nodding after 1 s, which a
    // slow start would reach within the 60 samples (1 s at 60 Hz).
    let cfg = example("127.0.0.42").replace("start_s = 1.0", "start_s = 1000.0");
    assert!(cfg.contains("start_s = 1000.0"));
    let old_goal = goal_of(&cfg);
    let path = dir.path("run.toml");
    std::fs::write(&path, &cfg).unwrap();
    // The simulated robot starts with the coil 15 cm out on the goal's axis; the tracker is exact
    // up to its 0.1 mm, 1 mrad noise, averaged over 60 distinct samples.
    let out = mocomp(&["teach-goal", "--config", &path, "--samples", "60"]);
    assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("wrote the goal"), "{text}");
    let new_text = std::fs::read_to_string(&path).unwrap();
    let taught = goal_of(&new_text);
    let expected = old_goal * Isometry3::translation(0.0, 0.0, -0.15);
    // The head is 0.1 m from the coil: 1 mrad of averaged rotation noise is 0.1 mm / √60 there.
    assert!(
        translation_error(&taught, &expected) < 2e-4,
        "{}",
        translation_error(&taught, &expected)
    );
    assert!(rotation_error(&taught, &expected) < 1e-3);
    // Everything else, comments included, is as it was.
    assert_eq!(
        cfg.lines().count(),
        new_text.lines().count(),
        "no line added or lost"
    );
    for (a, b) in cfg.lines().zip(new_text.lines()) {
        if !a.starts_with("head_from_coil") {
            assert_eq!(a, b);
        }
    }
    // --dry-run leaves the file alone.
    let out = mocomp(&["teach-goal", "--config", &path, "--dry-run"]);
    assert_success(&out);
    assert_eq!(std::fs::read_to_string(&path).unwrap(), new_text);
}

#[test]
fn teach_goal_with_a_name_keeps_the_pose_as_a_session_target_and_leaves_the_goal() {
    let dir = TempDir::new("mocomp-teach-named");
    let cfg = example("127.0.0.77").replace("start_s = 1.0", "start_s = 1000.0");
    let path = dir.path("run.toml");
    std::fs::write(&path, &cfg).unwrap();
    let out = mocomp(&[
        "teach-goal",
        "--config",
        &path,
        "--samples",
        "30",
        "--name",
        "hotspot",
        "--note",
        "APB, 62 % RMT",
    ]);
    assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("wrote target \"hotspot\""), "{text}");
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        cfg,
        "the goal is left"
    );
    // Beside the configuration, in the session's targets file: where the coil is (15 cm out on
    // the goal's axis at the start), with its note and when.
    let file = dir.path("session-targets.toml");
    let t =
        mocomp_session::Targets::parse(&file, &std::fs::read_to_string(&file).unwrap()).unwrap();
    let hot = t.get("hotspot").unwrap();
    let expected = goal_of(&cfg) * Isometry3::translation(0.0, 0.0, -0.15);
    assert!(translation_error(&hot.pose(), &expected) < 3e-4);
    assert_eq!(hot.note, "APB, 62 % RMT");
    assert!(hot.taught_at.ends_with("GMT"), "{}", hot.taught_at);
    // Taught again under the same name: replaced, not doubled.
    let out = mocomp(&[
        "teach-goal",
        "--config",
        &path,
        "--samples",
        "10",
        "--name",
        "hotspot",
    ]);
    assert_success(&out);
    let t =
        mocomp_session::Targets::parse(&file, &std::fs::read_to_string(&file).unwrap()).unwrap();
    assert_eq!(t.targets.len(), 1);
    assert_eq!(t.targets[0].note, "");
}

#[test]
fn teach_goal_refuses_a_coil_facing_away_from_the_head() {
    let dir = TempDir::new("mocomp-teach-bad");
    // The coil mounted the other way round: its +z (the approach axis) points away from the head.
    let cfg = example("127.0.0.43").replace(
        "flange_from_coil = [0.0, 0.0, 0.05, 0.0, 0.0, 0.0]",
        "flange_from_coil = [0.0, 0.0, 0.05, 3.141592653589793, 0.0, 0.0]",
    );
    // The simulated robot's default start uses the mounting too: start it where the good mounting
    // would start, 15 cm out, facing the head with the flange.
    let cfg = cfg.replace(
        "# initial_joints_rad = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0]",
        "initial_joints_rad = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0]",
    );
    assert!(cfg.contains("initial_joints_rad = [0.0"));
    let path = dir.path("run.toml");
    std::fs::write(&path, &cfg).unwrap();
    let out = mocomp(&["teach-goal", "--config", &path]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("points away from the head") || err.contains("inside"),
        "{err}"
    );
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        cfg,
        "nothing written"
    );
}

#[test]
fn calibrate_collect_finds_the_true_tracker_placement_and_run_uses_it() {
    let dir = TempDir::new("mocomp-collect");
    // The tracker is truly 11 mm and 0.8° from where the configuration says.
    let truth = [1.01, 0.09, 0.905, 2.01, -1.46, -0.58];
    let cfg = example("127.0.0.44")
        .replace(
            "# base_from_tracker = [1.0, 0.1, 0.9, 2.0019, -1.4693, -0.5718]",
            &format!("base_from_tracker = {truth:?}"),
        )
        .replace("poses = 15", "poses = 8")
        .replace("settle_s = 0.3", "settle_s = 0.1")
        .replace("joint_speed_rad_s = 0.8", "joint_speed_rad_s = 1.5")
        .replace("joint_accel_rad_s2 = 1.5", "joint_accel_rad_s2 = 4.0");
    assert!(cfg.contains("base_from_tracker = [1.01"));
    let path = dir.path("run.toml");
    std::fs::write(&path, &cfg).unwrap();
    let out = mocomp(&["calibrate", "collect", "--config", &path, "--quiet"]);
    assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("measured 8 of 8 poses"), "{text}");
    let calib = std::fs::read_to_string(dir.path("calibration.toml")).unwrap();
    let file = mocomp_calib::CalibrationFile::from_toml_str(&calib).unwrap();
    let (x, y) = file.transforms().unwrap();
    let true_y = iso_from_ur_pose(&truth).unwrap();
    assert!(translation_error(&y, &true_y) < 1e-3, "{text}");
    assert!(rotation_error(&y, &true_y) < 0.1f64.to_radians(), "{text}");
    let true_x = Isometry3::new(
        Vector3::new(0.0, 0.06, 0.02),
        Vector3::new(std::f64::consts::PI, 0.0, 0.0),
    );
    assert!(translation_error(&x, &true_x) < 5e-4, "{text}");
    // The pairs file re-solves with `calibrate solve`.
    let pairs = dir.path("calibration-pairs.csv");
    let out = mocomp(&[
        "calibrate",
        "solve",
        "--pairs",
        &pairs,
        "--robot",
        "ur3e",
        "--json",
    ]);
    assert_success(&out);
    // And `run` takes the file: with the true placement, the loop reaches and tracks the head.
    let cfg = cfg.replace(
        "# file = \"calibration.toml\"",
        "file = \"calibration.toml\"",
    );
    std::fs::write(&path, &cfg).unwrap();
    let out = mocomp(&["run", "--config", &path, "--seconds", "5", "--quiet"]);
    assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("reached the goal: tracking"), "{text}");
}
