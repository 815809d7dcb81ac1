//! The `mocomp` binary end to end: output formats, exit codes and one-line errors.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
use mocomp_geom::{iso_from_ur_pose, rotation_error, translation_error};
use mocomp_kin::{Arm, Model};
use std::process::Output;

mod common;
use common::{assert_success, mocomp};

fn stdout_json(out: &Output) -> serde_json::Value {
    assert_success(out);
    serde_json::from_slice(&out.stdout).expect("one JSON document")
}

fn floats(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[test]
fn fk_json_matches_library_and_published_values() {
    let out = mocomp(&[
        "fk",
        "--robot",
        "ur5",
        "--joints",
        "0,-1.5707963267948966,1.5707963267948966,0,1.5707963267948966,0",
        "--json",
    ]);
    let j = stdout_json(&out);
    let rows = j["base_from_flange"].as_array().unwrap();
    assert_eq!(rows.len(), 4);
    let t: Vec<f64> = rows.iter().map(|r| floats(r)[3]).collect();
    assert!((t[0] - -0.47455).abs() < 1e-9);
    assert!((t[1] - -0.10915).abs() < 1e-9);
    assert!((t[2] - 0.419509).abs() < 1e-9);
    assert_eq!(t[3], 1.0);
    let pose: [f64; 6] = floats(&j["pose"]).try_into().unwrap();
    let from_pose = iso_from_ur_pose(&pose).unwrap();
    let expected = Arm::new(Model::Ur5).fk(&[
        0.0,
        -std::f64::consts::FRAC_PI_2,
        std::f64::consts::FRAC_PI_2,
        0.0,
        std::f64::consts::FRAC_PI_2,
        0.0,
    ]);
    assert!(translation_error(&from_pose, &expected) < 1e-12);
    assert!(rotation_error(&from_pose, &expected) < 1e-12);
    assert!(j.get("base_from_tool").is_none());
}

#[test]
fn fk_with_tool_reports_both_frames() {
    let out = mocomp(&[
        "fk",
        "--robot",
        "ur3e",
        "--joints",
        "0.1,-1,1,0.2,0.3,0.4",
        "--tool",
        "0,0,0.1,0,0,0",
        "--json",
    ]);
    let j = stdout_json(&out);
    let flange: [f64; 6] = floats(&j["pose"]).try_into().unwrap();
    let tool: [f64; 6] = floats(&j["tool_pose"]).try_into().unwrap();
    let f = iso_from_ur_pose(&flange).unwrap();
    let t = iso_from_ur_pose(&tool).unwrap();
    // The tool origin is 0.1 m along the flange z axis.
    let expected = f * mocomp_geom::nalgebra::Point3::new(0.0, 0.0, 0.1);
    assert!((t.translation.vector - expected.coords).norm() < 1e-12);
}

#[test]
fn ik_json_lists_all_solutions_and_the_chosen_one() {
    let arm = Arm::new(Model::Ur3);
    let q = [0.3, -1.1, 1.2, -0.6, 1.1, 0.5];
    let pose = mocomp_geom::ur_pose_from_iso(&arm.fk(&q));
    let pose_arg = pose.map(|v| format!("{v:.17}")).join(",");
    let current = "0.31,-1.09,1.19,-0.61,1.12,0.49";
    let out = mocomp(&[
        "ik",
        "--robot",
        "ur3",
        "--pose",
        &pose_arg,
        "--current",
        current,
        "--json",
    ]);
    let j = stdout_json(&out);
    let sols = j["solutions"].as_array().unwrap();
    assert_eq!(sols.len(), 8);
    for s in sols {
        let joints: [f64; 6] = floats(&s["joints"]).try_into().unwrap();
        let back = arm.fk(&joints);
        assert!(translation_error(&back, &arm.fk(&q)) < 1e-9);
        for key in ["shoulder", "elbow", "wrist"] {
            assert!(s[key].is_string());
        }
    }
    let chosen: Vec<f64> = floats(&j["chosen"]);
    for (c, e) in chosen.iter().zip(q.iter()) {
        assert!((c - e).abs() < 1e-9, "chosen {chosen:?}, expected {q:?}");
    }
    let idx = j["chosen_index"].as_u64().unwrap() as usize;
    let b = mocomp_kin::BranchCoordinates::of(arm.geometry(), &q).branch();
    assert_eq!(sols[idx]["shoulder"], b.shoulder.as_str());
    assert_eq!(sols[idx]["elbow"], b.elbow.as_str());
    assert_eq!(sols[idx]["wrist"], b.wrist.as_str());
}

#[test]
fn ik_text_marks_the_chosen_solution() {
    let out = mocomp(&[
        "ik",
        "--robot",
        "ur5e",
        "--pose",
        "-0.4,-0.2,0.3,3.1,0.2,0",
        "--current",
        "0,-1.5,1.5,-1.5,-1.5,0",
    ]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert_eq!(
        text.lines().filter(|l| l.starts_with('*')).count(),
        1,
        "{text}"
    );
    assert!(text.contains("chosen: #"), "{text}");
}

fn expect_usage_error(args: &[&str], names: &str) {
    let out = mocomp(args);
    assert_eq!(out.status.code(), Some(2), "args {args:?}");
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err:?}");
    assert!(err.contains(names), "{err:?} should name {names}");
    assert!(out.stdout.is_empty());
}

#[test]
fn bad_input_is_one_line_naming_the_argument_exit_2() {
    expect_usage_error(&["fk", "--robot", "ur5", "--joints", "1,2,3"], "--joints");
    expect_usage_error(
        &["fk", "--robot", "ur5", "--joints", "1,2,3,4,5,x"],
        "element 6",
    );
    expect_usage_error(
        &["fk", "--robot", "ur5", "--joints", "1,2,3,4,5,NaN"],
        "--joints",
    );
    expect_usage_error(
        &["fk", "--robot", "ur4", "--joints", "0,0,0,0,0,0"],
        "--robot",
    );
    expect_usage_error(&["ik", "--robot", "ur5", "--pose", "0,0,0,0,0"], "--pose");
    expect_usage_error(
        &[
            "ik",
            "--robot",
            "ur5",
            "--pose",
            "0.3,0,0.3,0,3.1,0",
            "--current",
            "a",
        ],
        "--current",
    );
    expect_usage_error(
        &[
            "ik",
            "--robot",
            "ur5",
            "--pose",
            "0.3,0,0.3,0,3.1,0",
            "--margin",
            "-1",
        ],
        "--margin",
    );
    expect_usage_error(&["fk", "--joints", "0,0,0,0,0,0"], "--robot");
    expect_usage_error(
        &[
            "fk",
            "--robot",
            "ur5",
            "--joints",
            "0,0,0,0,0,0",
            "--calibration",
            "/nonexistent/cal.toml",
        ],
        "--calibration",
    );
}

#[test]
fn calibration_file_errors_name_the_file_and_mismatch() {
    let dir = std::env::temp_dir().join(format!("mocomp-cli-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cal.toml");
    std::fs::write(
        &path,
        "model = \"ur10\"\n[delta]\na = [0,0,0,0,0,0]\nd = [0,0,0,0,0,0]\nalpha = [0,0,0,0,0,0]\ntheta = [0.001,0,0,0,0,0]\n",
    )
    .unwrap();
    let p = path.to_str().unwrap();
    // A valid file for a UR10 works and changes the result.
    let out = mocomp(&[
        "fk",
        "--robot",
        "ur10",
        "--joints",
        "0,0,0,0,0,0",
        "--calibration",
        p,
        "--json",
    ]);
    let j = stdout_json(&out);
    let y = floats(&j["base_from_flange"][1])[3];
    assert!(
        y.abs() > 1e-4,
        "theta offset on joint 1 moves the flange sideways: {y}"
    );
    // The same file with --robot ur5 names the mismatch.
    expect_usage_error(
        &[
            "fk",
            "--robot",
            "ur5",
            "--joints",
            "0,0,0,0,0,0",
            "--calibration",
            p,
        ],
        "ur10",
    );
    std::fs::write(&path, "model = \"ur10\"\nbogus = 1\n").unwrap();
    expect_usage_error(
        &[
            "fk",
            "--robot",
            "ur10",
            "--joints",
            "0,0,0,0,0,0",
            "--calibration",
            p,
        ],
        "bogus",
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn unreachable_pose_is_exit_1_with_the_reason() {
    let out = mocomp(&["ik", "--robot", "ur3", "--pose", "2,0,0,0,0,0"]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.contains("unreachable") && err.contains("reach"),
        "{err}"
    );
}

#[test]
fn models_lists_every_model() {
    let out = mocomp(&["models", "--json"]);
    let j = stdout_json(&out);
    let names: Vec<&str> = j
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "ur3", "ur5", "ur10", "ur3e", "ur5e", "ur10e", "ur16e", "ur20", "ur30"
        ]
    );
    // UR3's wrist 3 has no limit: null in JSON.
    assert!(j[0]["upper_limits_rad"][5].is_null());
}
