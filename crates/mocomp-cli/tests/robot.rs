//! `mocomp ursim` and `mocomp robot` end to end (each on its own loopback address).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::{assert_success, mocomp};

use std::io::BufRead;
use std::process::{Command, Stdio};

#[test]
fn robot_stream_against_an_in_process_simulator_reports_its_figures() {
    let o = mocomp(&[
        "robot",
        "stream",
        "--host",
        "127.0.78.2",
        "--model",
        "ur3e",
        "--ursim",
        "--seconds",
        "2",
        "--json",
    ]);
    assert_success(&o);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["rate_hz"], 500.0);
    // One command per 2 ms deadline; a deadline the thread wakes too late for is skipped, never
    // made up in a burst: the commands and the skipped deadlines are each deadline once, however
    // many a loaded machine skips.
    let cycles = v["cycles"].as_u64().unwrap();
    let skipped = v["skipped_deadlines"].as_u64().unwrap();
    assert_eq!(cycles + skipped, 1000, "{v}");
    assert!(cycles > 0, "{v}");
    assert_eq!(v["protective_stop"], false);
    // The joints follow the target with the servo's lag (lookahead × speed) and no more. RMS,
    // not max: a client the host pauses for tens of ms falls behind for a moment, as it would.
    // For a sinusoid the lag's RMS is about 0.7 of its peak.
    let lag = v["expected_lag_rad"].as_f64().unwrap();
    let err = v["tracking_joint_rms_rad"].as_f64().unwrap();
    assert!(err > 0.4 * lag && err < 1.0 * lag, "{err} vs lag {lag}");
    let comp = v["lag_compensated_joint_rms_rad"].as_f64().unwrap();
    assert!(comp < 0.15 * lag, "{comp} vs lag {lag}");
}

#[test]
fn ursim_serves_the_standard_ports_and_robot_state_reads_it() {
    let mut sim = Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args([
            "ursim",
            "--model",
            "ur10",
            "--host",
            "127.0.78.3",
            "--seconds",
            "20",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufReader::new(sim.stdout.as_mut().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.contains("RTDE 127.0.78.3:30004"), "{first}");
    assert!(first.contains("dashboard 127.0.78.3:29999"), "{first}");
    assert!(first.contains("125 Hz"), "{first}");
    let o = mocomp(&["robot", "state", "--host", "127.0.78.3", "--json"]);
    sim.kill().ok();
    sim.wait().ok();
    assert_success(&o);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["robot_mode"], "RUNNING");
    assert_eq!(v["safety_mode"], "NORMAL");
    assert_eq!(v["runtime_state"], "PLAYING");
    assert!(v["fault"].is_null());
}

#[test]
fn unreachable_controller_and_bad_arguments_are_named() {
    let o = mocomp(&["robot", "state", "--host", "127.0.78.99"]);
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("127.0.78.99"), "{e}");
    let o = mocomp(&[
        "robot",
        "stream",
        "--host",
        "127.0.78.4",
        "--model",
        "ur5",
        "--seconds",
        "-1",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let o = mocomp(&["ursim", "--model", "ur99"]);
    assert_eq!(o.status.code(), Some(2));
}
