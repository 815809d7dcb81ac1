#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! `mocomp run` in a ROS 2 system, against Cyclone DDS (PyPI `cyclonedds`, the DDS under ROS 2's
//! `rmw_cyclonedds_cpp`) as the other nodes: with `--ros2` Cyclone receives the live loop's joint
//! states, TF, poses and diagnostics; with `tracker.source = "ros2"` the loop compensates on the
//! head poses Cyclone publishes. In the test script's network namespace (loopback only); each test
//! its own DDS domain.

mod common;
use common::example_changed as example;
use common::run_args;
use mocomp_geom::iso_from_ur_pose;
use mocomp_testkit::{PythonPeer, TempDir, assert_loopback_only};
use serde_json::{Value, json};
use std::process::{Child, Command, Stdio};

fn spawn_run(config: &str, seconds: &str, domain: u16, extra: &[&str]) -> Child {
    Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args(run_args(config, seconds, extra))
        .env("ROS_DOMAIN_ID", domain.to_string())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn summary(child: Child) -> Value {
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "exit {:?}: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The run's events, in words.
fn event_names(v: &Value) -> Vec<&str> {
    v["event_log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e[1].as_str().unwrap())
        .collect()
}

fn peer() -> PythonPeer {
    PythonPeer::start("cyclonedds_peer.py", "cyclonedds", "11.0.1")
}

#[test]
fn cyclone_sees_the_live_loop_joint_states_tf_poses_and_diagnostics() {
    assert_loopback_only();
    let dir = TempDir::new("mocomp-ros2-run");
    let cfg = example(&dir, "127.0.0.80", &[]);
    let mut py = peer();
    let child = spawn_run(&cfg, "7", 21, &["--ros2"]);
    // Until the run has ended and nothing more comes: counted, not timed.
    let seen = py
        .request(&json!({"op": "listen", "seconds": 120.0, "wait": 60, "idle": 2.0, "domain": 21}));
    let v = summary(child);
    eprintln!(
        "cyclone saw: counts {} latency {}; mocomp: {}",
        seen["counts"], seen["latency_ms"], v["ros2"]
    );
    // Joint states are reliable: every cycle from Cyclone's discovery on (seconds of a 7 s
    // run), none the loop did not run; the node dropped none, and Cyclone got nothing it did not
    // publish (joint states, TF, the coil and, once known, the head a cycle; diagnostics).
    let js = seen["counts"]["joint_states"].as_u64().unwrap();
    let cycles = v["cycles"].as_u64().unwrap();
    assert!(
        js >= 1000 && js <= cycles,
        "{js} of {cycles} cycles; {seen}"
    );
    assert_eq!(v["ros2"]["dropped"], 0, "{v}");
    let published = v["ros2"]["published"].as_u64().unwrap();
    let got: u64 = seen["counts"]
        .as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert!(
        published >= 3 * cycles && got <= published,
        "{got} of {published}; {v}"
    );
    let last = &seen["last"];
    let names = last["joint_states"]["name"].as_array().unwrap();
    assert_eq!(names[0], "shoulder_pan_joint");
    assert_eq!(
        last["joint_states"]["position"].as_array().unwrap().len(),
        6
    );
    let frames: Vec<&str> = last["tf"]["transforms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["child_frame_id"].as_str().unwrap())
        .collect();
    assert_eq!(frames, ["tool0", "tracker", "head", "coil_goal"]);
    // The tracker where the calibration puts it, the goal as configured.
    let tracker = &last["tf"]["transforms"][1]["transform"]["translation"];
    assert!(
        (tracker["x"].as_f64().unwrap() - 1.0).abs() < 1e-12,
        "{tracker}"
    );
    let goal = &last["tf"]["transforms"][3]["transform"]["translation"];
    assert!(
        (goal["z"].as_f64().unwrap() - 0.113).abs() < 1e-12,
        "{goal}"
    );
    // The coil: the flange's pose moved 5 cm along its axis (the coil's mounting).
    let coil = &last["coil_pose"]["pose"]["position"];
    assert!(coil["z"].as_f64().is_some());
    let diag = &last["diagnostics"]["status"][0];
    assert_eq!(diag["hardware_id"], "mocomp");
    let keys: Vec<&str> = diag["values"]
        .as_array()
        .unwrap()
        .iter()
        .map(|kv| kv["key"].as_str().unwrap())
        .collect();
    assert!(
        keys.contains(&"rate_hz") && keys.contains(&"deviation_max_mm"),
        "{diag}"
    );
}

#[test]
fn hold_and_resume_are_ros_2_services_a_cyclone_node_calls() {
    assert_loopback_only();
    let dir = TempDir::new("mocomp-ros2-services");
    let cfg = example(
        &dir,
        "127.0.0.82",
        &[("kind = \"nods\"", "kind = \"still\"")],
    );
    let mut text = std::fs::read_to_string(&cfg).unwrap();
    text.push_str("\n[ros2]\nenabled = true\nservice_mapping = \"cyclone\"\n");
    std::fs::write(&cfg, text).unwrap();
    let mut py = peer();
    // Long enough for any machine: ended by the test (SIGINT, as Ctrl-C) once it has seen what
    // it waits for.
    let child = spawn_run(&cfg, "300", 23, &[]);
    let diag = |py: &mut PythonPeer, message: &str| {
        let d =
            py.request(&json!({"op": "wait_diag", "message": message, "wait": 120, "domain": 23}));
        assert!(d["error"].is_null(), "{d}");
    };
    diag(&mut py, "tracking");
    let held = py.request(
        &json!({"op": "call", "service": "/mocomp/hold", "seq": 1, "wait": 60, "domain": 23}),
    );
    assert_eq!(
        held,
        json!({"success": true, "message": "hold requested"}),
        "{held}"
    );
    diag(&mut py, "holding (Operator)");
    let resumed = py.request(
        &json!({"op": "call", "service": "/mocomp/resume", "seq": 2, "wait": 60, "domain": 23}),
    );
    assert_eq!(resumed["success"], true, "{resumed}");
    diag(&mut py, "tracking");
    let interrupted = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(interrupted.success());
    let v = summary(child);
    let events = event_names(&v);
    let hold = events.iter().position(|e| *e == "Hold(Operator)");
    assert!(hold.is_some(), "{events:?}");
    assert!(
        events[hold.unwrap()..].contains(&"Resume") || events[hold.unwrap()..].contains(&"Reached"),
        "{events:?}"
    );
}

#[test]
fn the_loop_compensates_on_head_poses_cyclone_publishes() {
    assert_loopback_only();
    let dir = TempDir::new("mocomp-ros2-head");
    // The head's poses come from ROS 2: the simulated robot, no simulated tracker.
    let cfg = example(
        &dir,
        "127.0.0.81",
        &[("source = \"simulated\"", "source = \"ros2\"")],
    );
    // The head where the example's simulated head rests, in the tracker's frame.
    let base_from_tracker = iso_from_ur_pose(&[1.0, 0.1, 0.9, 2.0019, -1.4693, -0.5718]).unwrap();
    let base_from_head = iso_from_ur_pose(&[0.30, -0.12, -0.02, 0.0, 0.0, 0.3]).unwrap();
    let h = base_from_tracker.inverse() * base_from_head;
    let (t, q) = (h.translation.vector, h.rotation);
    // Cyclone publishes until the run has gone; the run is ended (SIGINT) once it has tracked.
    let child = spawn_run(&cfg, "300", 22, &[]);
    let pose = [t.x, t.y, t.z, q.i, q.j, q.k, q.w];
    let publisher = std::thread::spawn(move || {
        peer().request(
            &json!({"op": "publish_head", "topic": "/mocomp/tracker/head",
            "rate_hz": 60, "seconds": 300.0, "wait": 60, "domain": 22, "noise_m": 0.0001,
            "pose": pose, "until_unmatched": true}),
        )
    });
    let mut py = peer();
    let d =
        py.request(&json!({"op": "wait_diag", "message": "tracking", "wait": 120, "domain": 22}));
    assert!(d["error"].is_null(), "{d}");
    // A second of tracking on the loop's own clock: its diagnostics, once a second, twice more.
    for _ in 0..2 {
        let d = py.request(&json!({"op": "wait_diag", "message": "", "wait": 60, "domain": 22}));
        assert!(d["error"].is_null(), "{d}");
    }
    let interrupted = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(interrupted.success());
    let v = summary(child);
    let published = publisher.join().unwrap();
    eprintln!(
        "published {published}; mocomp: tracking {}% deviation rms {} mm",
        v["tracking_percent"], v["deviation_rms_mm"]
    );
    assert_eq!(published["matched"], true);
    let events = event_names(&v);
    // The planned approach reached the goal on the head Cyclone reports, and the loop tracked it.
    assert!(common::reached(&v), "{events:?}: {v}");
    assert!(v["deviation_rms_mm"].as_f64().unwrap() < 1.0, "{v}");
}
