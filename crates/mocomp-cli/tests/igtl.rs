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

/// The hostile messages kept by mocomp-igtl's fuzzing (valid CRCs, damaged layouts, a body of
/// 2⁶³ bytes): what, the bytes.
fn hostile() -> Vec<(String, Vec<u8>)> {
    mocomp_testkit::fuzz::kept_cases(include_str!("../../mocomp-igtl/tests/data/hostile.tsv"))
        .into_iter()
        .map(|k| (k.what, k.bytes))
        .collect()
}

fn pose_at(x_mm: f32) -> Vec<u8> {
    use mocomp_igtl::{Body, Message, encode};
    let mut f = [0f32; 12];
    (f[0], f[4], f[8]) = (1.0, 1.0, 1.0);
    f[9] = x_mm;
    encode(&Message::new("TRANSFORM", "HeadToTracker", Body::Transform(f)).unwrap())
}

#[test]
fn listen_keeps_receiving_after_each_hostile_message_and_names_it() {
    use std::io::Write;
    let kept = hostile();
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let n = kept.len();
    // One connection: a valid pose before and after each hostile message. The last (a body of
    // 2⁶³ bytes) leaves the stream out of step: the client must drop it, connect again and go on
    // with the second connection's poses.
    let server = std::thread::spawn(move || {
        let (mut first, _) = listener.accept().unwrap();
        for (k, (_, bytes)) in kept.iter().enumerate() {
            first.write_all(&pose_at(k as f32)).unwrap();
            first.write_all(bytes).unwrap();
        }
        first.flush().unwrap();
        let (mut second, _) = listener.accept().unwrap();
        for k in 0..3 {
            second.write_all(&pose_at((n + k) as f32)).unwrap();
        }
        // Held open until the listener has read them and gone.
        let mut sink = [0u8; 64];
        let _ = std::io::Read::read(&mut second, &mut sink);
    });
    let out = Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args([
            "listen",
            "--igtl",
            &addr,
            "--device",
            "HeadToTracker",
            "--count",
            &(n + 3).to_string(),
            "--json",
            "--timeout",
            "60",
        ])
        .output()
        .unwrap();
    assert_success(&out);
    server.join().unwrap();
    let xs: Vec<f64> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            v["tracker_from_marker"][0][3].as_f64().unwrap()
        })
        .collect();
    let expected: Vec<f64> = (0..n + 3).map(|k| k as f64).collect();
    assert_eq!(xs, expected, "every valid pose, in order");
    let err = String::from_utf8(out.stderr).unwrap();
    // Three damaged layouts dropped one by one, one stream out of step, one reconnect, named.
    assert!(
        err.contains(
            "4 damaged (0 CRC errors, 3 malformed, 1 streams out of step, 0 reader failures)"
        ) && err.contains("1 reconnects")
            && err.contains("9223372036854775808-byte body"),
        "{err}"
    );
}

#[test]
fn run_keeps_tracking_through_hostile_messages_and_counts_them() {
    use mocomp_geom::iso_from_ur_pose;
    use mocomp_igtl::message::transform_floats;
    use mocomp_igtl::{Body, Message, encode};
    use std::io::Write;
    use std::time::Duration;
    let d = TempDir::new("igtl-run-hostile");
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    // The example's still head, seen from its tracker: what a real tracker would send.
    let base_from_tracker = iso_from_ur_pose(&[1.0, 0.1, 0.9, 2.0019, -1.4693, -0.5718]).unwrap();
    let base_from_head = iso_from_ur_pose(&[0.30, -0.12, -0.02, 0.0, 0.0, 0.3]).unwrap();
    let tracker_from_head = base_from_tracker.inverse() * base_from_head;
    // A real tracker's noise (a frozen stream is a fault of its own), 0.05 mm, seeded.
    let mut rng = mocomp_testkit::SplitMix64(50);
    let mut pose = move || {
        let mut f = transform_floats(&tracker_from_head);
        for v in &mut f[9..12] {
            *v += 0.05 * rng.gauss() as f32;
        }
        encode(&Message::new("TRANSFORM", "HeadToTracker", Body::Transform(f)).unwrap())
    };
    let kept = hostile();
    let server = std::thread::spawn(move || {
        let tick = || std::thread::sleep(Duration::from_millis(10));
        let (mut first, _) = listener.accept().unwrap();
        for (_, bytes) in &kept {
            for _ in 0..20 {
                first.write_all(&pose()).unwrap();
                tick();
            }
            first.write_all(bytes).unwrap();
        }
        // After the body of 2⁶³ bytes the client connects again; stream until it goes.
        let (mut second, _) = listener.accept().unwrap();
        while second.write_all(&pose()).is_ok() {
            tick();
        }
    });
    let path = common::example_changed(
        &d,
        "127.0.0.43",
        &[(
            "source = \"simulated\" ",
            &format!("source = \"openigtlink\"\nigtl = \"{addr}\" "),
        )],
    );
    let out = common::mocomp(&common::run_args(&path, "8", &[]));
    assert_success(&out);
    server.join().unwrap();
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let t = &v["tracker"];
    assert_eq!(t["messages_dropped"], 3, "{t}");
    assert_eq!(t["streams_dropped"], 1, "{t}");
    assert_eq!(t["connections"], 2, "{t}");
    assert_eq!(t["reader_failures"], 0, "{t}");
    let events = v["event_log"].as_array().unwrap();
    assert!(common::reached(&v), "{events:?}");
}
