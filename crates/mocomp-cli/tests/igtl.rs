//! `mocomp serve-poses` and `mocomp listen` against each other over loopback.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::assert_success;

use mocomp_testkit::TempDir;
use std::io::BufRead;
use std::process::{Command, Stdio};

#[test]
fn listen_prints_what_serve_poses_sends() {
    let d = TempDir::new("igtl-cli");
    let feed = d.path("poses.jsonl");
    let lines: Vec<String> = (0..5)
        .map(|k| {
            format!(
                "{{\"tracker_from_marker\": [[1,0,0,{}],[0,1,0,-20.5],[0,0,1,950],[0,0,0,1]]}}",
                10 * k
            )
        })
        .collect();
    std::fs::write(&feed, lines.join("\n")).unwrap();
    // Port 0: the server binds what is free and prints the address it got.
    let mut server = Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args([
            "serve-poses",
            "--igtl-port",
            "0",
            "--from",
            &feed,
            "--rate",
            "100",
            "--device",
            "HeadToTracker",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until it listens.
    let mut first = String::new();
    std::io::BufReader::new(server.stdout.as_mut().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(first.contains("waiting for a client"), "{first}");
    let addr = first
        .split(" on ")
        .nth(1)
        .and_then(|r| r.split(';').next())
        .unwrap()
        .to_string();
    assert!(
        addr.starts_with("127.0.0.1:") && !addr.ends_with(":0"),
        "{first}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args([
            "listen",
            "--igtl",
            &addr,
            "--device",
            "HeadToTracker",
            "--count",
            "5",
            "--json",
            "--timeout",
            "10",
        ])
        .output()
        .unwrap();
    assert_success(&out);
    let text = String::from_utf8(out.stdout).unwrap();
    let got: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(got.len(), 5);
    for (k, v) in got.iter().enumerate() {
        assert_eq!(v["device"], "HeadToTracker");
        assert_eq!(v["valid"], true);
        assert!(v["t"].as_f64().unwrap() > 1.6e9, "a wall-clock timestamp");
        assert!((v["tracker_from_marker"][0][3].as_f64().unwrap() - 10.0 * k as f64).abs() < 1e-4);
        assert!((v["tracker_from_marker"][2][3].as_f64().unwrap() - 950.0).abs() < 1e-3);
    }
    assert!(server.wait().unwrap().success());
}

#[test]
fn listen_without_a_server_is_exit_1_with_the_reason() {
    // An address of this test's own, where nothing listens: the connection is refused.
    let out = Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args(["listen", "--igtl", "127.0.88.1:18944", "--timeout", "0.5"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("no pose") && err.contains("refused"), "{err}");
}

#[test]
fn serve_poses_rejects_a_bad_feed() {
    let d = TempDir::new("igtl-cli-bad");
    let feed = d.path("bad.jsonl");
    std::fs::write(
        &feed,
        "{\"tracker_from_marker\": [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}\n",
    )
    .unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args(["serve-poses", "--igtl-port", "0", "--from", &feed])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(
        err.contains("line 1") && err.contains("orthonormal"),
        "{err}"
    );
}
