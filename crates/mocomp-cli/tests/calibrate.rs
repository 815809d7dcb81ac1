//! `mocomp calibrate`: synth → solve round trip, result file, and clear errors for malformed and
//! degenerate pairs files.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::{assert_success, mocomp};

use mocomp_calib::CalibrationFile;
use mocomp_geom::nalgebra::Matrix4;
use mocomp_geom::{iso_from_matrix, iso_from_ur_pose, translation_error};
use mocomp_testkit::TempDir;

#[test]
fn synth_then_solve_recovers_x_and_y() {
    let dir = TempDir::new("calib-ok");
    let pairs = dir.path("pairs.csv");
    let x = "0.02,0.04,0.11,0.1,-0.2,0.9";
    let out = mocomp(&[
        "calibrate",
        "synth",
        "--out",
        &pairs,
        "--count",
        "30",
        "--seed",
        "4",
        "--x",
        x,
    ]);
    assert_success(&out);
    let toml = dir.path("calib.toml");
    let out = mocomp(&[
        "calibrate",
        "solve",
        "--pairs",
        &pairs,
        "--out",
        &toml,
        "--json",
    ]);
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in ["X", "Y", "rms_mm", "rms_deg", "max_mm", "outliers"] {
        assert!(j.get(key).is_some(), "missing {key}");
    }
    let m = Matrix4::from_fn(|r, c| j["X"][r][c].as_f64().unwrap());
    let got = iso_from_matrix(&m, 1e-9).unwrap();
    let want = iso_from_ur_pose(&[0.02, 0.04, 0.11, 0.1, -0.2, 0.9]).unwrap();
    assert!(
        translation_error(&got, &want) < 1e-3,
        "X within a millimetre"
    );
    assert!(j["rms_mm"].as_f64().unwrap() < 0.5);
    // The result file reads back to the same X.
    let file = CalibrationFile::from_toml_str(&std::fs::read_to_string(&toml).unwrap()).unwrap();
    let (fx, _) = file.transforms().unwrap();
    assert!(translation_error(&fx, &got) < 1e-12);
    // Every method runs.
    for method in ["li", "shah", "refined"] {
        let out = mocomp(&["calibrate", "solve", "--pairs", &pairs, "--method", method]);
        assert!(out.status.success());
        let text = String::from_utf8(out.stdout).unwrap();
        assert!(text.contains(&format!("method {method}")), "{text}");
    }
}

const HEADER: &str = "flange_x_m,flange_y_m,flange_z_m,flange_rx,flange_ry,flange_rz,marker_x_mm,marker_y_mm,marker_z_mm,marker_qw,marker_qx,marker_qy,marker_qz";

fn expect_error(dir: &TempDir, name: &str, content: &str, needles: &[&str]) {
    let path = dir.path(name);
    std::fs::write(&path, content).unwrap();
    let out = mocomp(&["calibrate", "solve", "--pairs", &path]);
    assert_eq!(out.status.code(), Some(2), "{name}");
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(
        err.trim_end().lines().count(),
        1,
        "{name}: one line: {err:?}"
    );
    for n in needles {
        assert!(err.contains(n), "{name}: {err:?} should contain {n:?}");
    }
}

#[test]
fn malformed_pairs_files_name_line_and_column() {
    let dir = TempDir::new("calib-bad");
    let good = "0.3,-0.2,0.4,0,3.1,0,100,20,1200,1,0,0,0";
    expect_error(
        &dir,
        "cell.csv",
        &format!("{HEADER}\n{good}\n0.3,-0.2,x,0,3.1,0,100,20,1200,1,0,0,0\n"),
        &["cell.csv", "line 3", "column 3", "flange_z_m"],
    );
    expect_error(
        &dir,
        "short.csv",
        &format!("{HEADER}\n{good}\n0.3,-0.2\n"),
        &["line 3", "2 fields"],
    );
    expect_error(
        &dir,
        "quat.csv",
        &format!("{HEADER}\n0.3,-0.2,0.4,0,3.1,0,100,20,1200,2,0,0,0\n"),
        &["line 2", "column 10", "quaternion"],
    );
    expect_error(
        &dir,
        "missing.csv",
        &format!("{}\n", HEADER.replace(",marker_qw", "")),
        &["missing column(s) marker_qw"],
    );
    expect_error(
        &dir,
        "unknown.csv",
        &format!("{HEADER},temp_c\n"),
        &["unknown column \"temp_c\"", "column 14"],
    );
    expect_error(&dir, "empty.csv", "", &["empty.csv"]);
    expect_error(
        &dir,
        "header-only.csv",
        &format!("{HEADER}\n"),
        &["no pairs"],
    );
    expect_error(
        &dir,
        "nan.csv",
        &format!("{HEADER}\n0.3,-0.2,0.4,0,3.1,inf,100,20,1200,1,0,0,0\n"),
        &["column 6", "not a finite number"],
    );
    let joints = "q1,q2,q3,q4,q5,q6,marker_x_mm,marker_y_mm,marker_z_mm,marker_qw,marker_qx,marker_qy,marker_qz\n0,0,0,0,0,0,1,2,3,1,0,0,0\n";
    expect_error(&dir, "joints.csv", joints, &["--robot"]);
    // A missing file.
    let out = mocomp(&["calibrate", "solve", "--pairs", &dir.path("nope.csv")]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8(out.stderr).unwrap().contains("--pairs"));
}

#[test]
fn degenerate_pairs_files_are_named() {
    let dir = TempDir::new("calib-degenerate");
    // Two pairs only.
    let two = format!(
        "{HEADER}\n0.3,-0.2,0.4,0,3.1,0,100,20,1200,1,0,0,0\n0.35,-0.2,0.4,0.3,3.1,0,110,25,1150,1,0,0,0\n"
    );
    expect_error(&dir, "two.csv", &two, &["2 pairs", "at least 3"]);
    // A duplicated line: synthesise, then repeat the second data line at the end.
    let pairs = dir.path("dup.csv");
    assert!(
        mocomp(&["calibrate", "synth", "--out", &pairs, "--count", "8"])
            .status
            .success()
    );
    let text = std::fs::read_to_string(&pairs).unwrap();
    let data: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    let dup = format!("{}\n{}\n", text.trim_end(), data[2]);
    expect_error(
        &dir,
        "dup2.csv",
        &dup,
        &["same robot pose", "line 6", "line 13"],
    );
    // Rotations about one axis: the flange turns about its z only.
    let mut single = format!("{HEADER}\n");
    for i in 0..6 {
        let a = 0.3 * i as f64;
        single.push_str(&format!(
            "0.3,-0.2,0.4,0,0,{a},{},{},1200,{},0,0,{}\n",
            100.0 + i as f64,
            20.0,
            (a / 2.0).cos(),
            (a / 2.0).sin()
        ));
    }
    expect_error(&dir, "single.csv", &single, &["one axis"]);
}

#[test]
fn plan_prints_poses_or_says_why_not() {
    let out = mocomp(&[
        "calibrate",
        "plan",
        "--robot",
        "ur3",
        "--center",
        "0.25,-0.15,0.3,2.2,-2.2,0",
        "--count",
        "8",
        "--json",
    ]);
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["poses"].as_array().unwrap().len(), 8);
    assert!(j["tour_time_s"].as_f64().unwrap() > 0.0);
    // A centre out of reach is exit 1 with the reason.
    let out = mocomp(&[
        "calibrate",
        "plan",
        "--robot",
        "ur3",
        "--center",
        "2,0,0.3,0,3.1,0",
    ]);
    assert_ne!(out.status.code(), Some(0));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.contains("--center") || err.contains("unreachable"),
        "{err}"
    );
}
