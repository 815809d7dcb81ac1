//! mocomp's ROS 2 node against Cyclone DDS (PyPI `cyclonedds`, the DDS under ROS 2's
//! `rmw_cyclonedds_cpp`) speaking ROS 2's DDS names and types (`rt/joint_states`,
//! `sensor_msgs::msg::dds_::JointState_`): Cyclone receives our joint states, TF, poses and
//! diagnostics with the values sent and at the rate sent; we take the head poses Cyclone publishes.
//! In the test script's network namespace (loopback only): nothing leaves the machine.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_geom::{Clock, MonotonicClock, PoseSource};
use mocomp_ros2::node::UR_JOINTS;
use mocomp_ros2::{Out, Ros2Bridge, Ros2Config, Snapshot, Status};
use mocomp_testkit::{PythonPeer, assert_loopback_only};
use serde_json::{Value, json};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

fn peer() -> PythonPeer {
    PythonPeer::start("cyclonedds_peer.py", "cyclonedds", "11.0.1")
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// Cycle `k` of a run stamped from `t0` (Unix s), 2 ms apart: joint 1 at k mrad, and the stamp
/// says which cycle a message of any topic came from.
fn snapshot(k: u64, t0: f64) -> Snapshot {
    let a = k as f64 * 1e-3;
    Snapshot {
        stamp_unix_s: t0 + 0.002 * k as f64,
        q: [a, -1.3, 1.6, -1.87, -1.57, 0.25],
        qd: [0.5, 0.0, 0.0, 0.0, 0.0, -0.1],
        base_from_flange: Isometry3::new(Vector3::new(0.3, -0.1, 0.4), Vector3::new(3.1, 0.0, 0.0)),
        base_from_coil: Isometry3::new(Vector3::new(0.3, -0.1, 0.35), Vector3::new(3.1, 0.0, 0.0)),
        base_from_tracker: Isometry3::new(
            Vector3::new(1.0, 0.1, 0.9),
            Vector3::new(2.0, -1.47, -0.57),
        ),
        tracker_from_head: Some(Isometry3::new(
            Vector3::new(0.05, 0.02, 1.1),
            Vector3::new(0.1, 0.2, 0.3),
        )),
        head_from_coil_goal: Isometry3::new(
            Vector3::new(0.0, 0.0, 0.113),
            Vector3::new(std::f64::consts::PI, 0.0, 0.0),
        ),
    }
}

fn close(v: &Value, x: f64) -> bool {
    (v.as_f64().unwrap() - x).abs() < 1e-12
}

#[test]
fn cyclone_receives_our_topics_with_their_values_and_rates_and_we_take_its_head_poses() {
    assert_loopback_only();
    let mut py = peer();
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    let cfg = Ros2Config {
        head_topic: Some("/mocomp/tracker/head".into()),
        ..Ros2Config::default()
    };
    let bridge = Arc::new(Ros2Bridge::start(&cfg, None).unwrap());
    // The loop's side: 1,500 cycles, one every 2 ms (500 Hz, an e-Series), the status every
    // 500 (3). Cyclone listens until nothing more comes: what is counted is what was sent and
    // what arrived, however fast this machine ran them.
    const CYCLES: u64 = 1500;
    let t0_unix = unix_now();
    let sender = {
        let bridge = Arc::clone(&bridge);
        std::thread::spawn(move || {
            let t0 = Instant::now();
            for k in 0..CYCLES {
                bridge.send(Out::Cycle(Box::new(snapshot(k, t0_unix))));
                if k.is_multiple_of(500) {
                    bridge.send(Out::Status(Status {
                        stamp_unix_s: unix_now(),
                        level: 1,
                        message: "holding (Operator)".into(),
                        values: vec![("rate_hz".into(), "500".into())],
                    }));
                }
                let due = t0 + Duration::from_micros(2000 * (k + 1));
                std::thread::sleep(due.saturating_duration_since(Instant::now()));
            }
        })
    };
    // Cyclone's process not scheduled for 0.4 s mid-stream (its receive threads too: nothing is
    // acknowledged): what a busy machine does to a subscriber, here on purpose. The reliable
    // topics must come through whole all the same.
    let stalled = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let staller = {
        let (pid, stalled) = (py.pid().to_string(), Arc::clone(&stalled));
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(1200));
            let signal = |s: &str| {
                std::process::Command::new("kill")
                    .args([s, &pid])
                    .status()
                    .is_ok_and(|st| st.success())
            };
            if signal("-STOP") {
                std::thread::sleep(Duration::from_millis(400));
                stalled.store(signal("-CONT"), std::sync::atomic::Ordering::Relaxed);
            }
        })
    };
    let seen = py.request(&json!({"op": "listen", "seconds": 120.0, "wait": 60, "idle": 2.0}));
    sender.join().unwrap();
    staller.join().unwrap();
    assert!(
        stalled.load(std::sync::atomic::Ordering::Relaxed),
        "the peer was stopped and continued"
    );
    eprintln!(
        "cyclone saw: counts {} rates {} latency {}; handed to the node {}, dropped {}",
        seen["counts"],
        seen["rates_hz"],
        seen["latency_ms"],
        CYCLES + 3 - bridge.dropped(),
        bridge.dropped()
    );
    // The loop's queue to the node is never full at 500 Hz (it would drop, not block).
    assert_eq!(bridge.dropped(), 0, "{seen}");
    // Every cycle reaches Cyclone (joint states and TF are reliable; its readers keep all, so a
    // busy machine that leaves it unscheduled, as above, loses nothing) from the first it got on
    // each topic (the ones before its reader was discovered are gone, as ROS 2's volatile topics
    // lose them): the stamp says which cycle a message is.
    let cycle_of = |header: &Value| {
        let t = header["stamp"]["sec"].as_f64().unwrap()
            + header["stamp"]["nanosec"].as_f64().unwrap() * 1e-9;
        ((t - t0_unix) / 0.002).round() as u64
    };
    let firsts = [
        ("joint_states", &seen["first"]["joint_states"]["header"]),
        ("tf", &seen["first"]["tf"]["transforms"][0]["header"]),
    ];
    for (topic, header) in firsts {
        let first = cycle_of(header);
        let n = seen["counts"][topic].as_u64().unwrap();
        assert_eq!(n, CYCLES - first, "{topic}: from cycle {first}; {seen}");
    }
    assert_eq!(
        (seen["first"]["joint_states"]["position"][0]
            .as_f64()
            .unwrap()
            * 1e3)
            .round() as u64,
        cycle_of(&seen["first"]["joint_states"]["header"]),
        "the stamp is the cycle's"
    );
    // The poses are sensor data (best effort): some, never more than sent.
    for topic in ["coil_pose", "head_pose"] {
        let n = seen["counts"][topic].as_u64().unwrap();
        assert!(n > 0 && n <= CYCLES, "{topic}: {n}");
    }
    let diagnostics = seen["counts"]["diagnostics"].as_u64().unwrap();
    assert!((1..=3).contains(&diagnostics), "{diagnostics}");

    // The values.
    let last = &seen["last"];
    let js = &last["joint_states"];
    let names: Vec<&str> = js["name"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert_eq!(names, UR_JOINTS);
    let q = js["position"].as_array().unwrap();
    assert!(close(&q[1], -1.3) && close(&q[5], 0.25), "{js}");
    assert!(q[0].as_f64().unwrap() > 1.0, "a late cycle's joint 1: {js}");
    assert!(close(&js["velocity"][5], -0.1));
    assert!(js["effort"].as_array().unwrap().is_empty());
    let stamp = js["header"]["stamp"]["sec"].as_i64().unwrap() as f64;
    assert!((stamp - unix_now()).abs() < 10.0, "stamped now: {js}");

    let s = snapshot(0, t0_unix);
    let tf = last["tf"]["transforms"].as_array().unwrap();
    let frames: Vec<(&str, &str)> = tf
        .iter()
        .map(|t| {
            (
                t["header"]["frame_id"].as_str().unwrap(),
                t["child_frame_id"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        frames,
        [
            ("base", "tool0"),
            ("base", "tracker"),
            ("tracker", "head"),
            ("head", "coil_goal")
        ]
    );
    let tr = &tf[1]["transform"];
    assert!(close(&tr["translation"]["x"], 1.0) && close(&tr["translation"]["z"], 0.9));
    let r = s.base_from_tracker.rotation;
    let (qx, qw) = (
        tr["rotation"]["x"].as_f64().unwrap(),
        tr["rotation"]["w"].as_f64().unwrap(),
    );
    assert!((qx - r.i).abs() < 1e-12 && (qw - r.w).abs() < 1e-12, "{tr}");
    let goal = &tf[3]["transform"]["translation"];
    assert!(close(&goal["z"], 0.113));

    let coil = &last["coil_pose"];
    assert_eq!(coil["header"]["frame_id"], "base");
    assert!(close(&coil["pose"]["position"]["z"], 0.35), "{coil}");
    // The head in the base frame: base_from_tracker · tracker_from_head.
    let head = &last["head_pose"]["pose"]["position"];
    let expected = (s.base_from_tracker * s.tracker_from_head.unwrap())
        .translation
        .vector;
    assert!(
        (head["x"].as_f64().unwrap() - expected.x).abs() < 1e-12,
        "{head}"
    );
    let diag = &last["diagnostics"]["status"][0];
    assert_eq!(diag["level"], 1);
    assert_eq!(diag["message"], "holding (Operator)");
    assert_eq!(diag["values"][0]["key"], "rate_hz");

    // Latency, publish → Cyclone's reader, on loopback (printed; the benchmark is bench/).
    assert!(seen["latency_ms"]["n"].as_u64().unwrap() > 1000);

    // The other way: Cyclone publishes the head at 100 Hz for 2 s; our head source takes the
    // poses with their stamps on our clock. Counted by the node as they arrive, not by how
    // often this test could look.
    let mut source = bridge.head_source(Arc::clone(&clock));
    let pose = [
        0.01,
        -0.02,
        1.2,
        0.0,
        0.0,
        0.38268343236508984,
        0.9238795325112867,
    ];
    let asked = clock.now_s();
    let published = py.request(
        &json!({"op": "publish_head", "topic": "/mocomp/tracker/head",
        "rate_hz": 100, "seconds": 2.0, "pose": pose, "wait": 20}),
    );
    assert_eq!(published["matched"], true, "{published}");
    let sent = published["published"].as_u64().unwrap();
    // Until nothing more arrives.
    let mut got = source.received();
    loop {
        std::thread::sleep(Duration::from_millis(500));
        let now = source.received();
        if now == got {
            break;
        }
        got = now;
    }
    eprintln!("head poses: {published}, received {got}");
    // Best effort: none invented, some arrived (how many a busy machine keeps is printed).
    assert!(got > 0 && got <= sent, "{got} of {sent}");
    let s = source.latest().expect("a head pose from Cyclone");
    let t = s.tracker_from_marker.translation.vector;
    assert!((t - Vector3::new(0.01, -0.02, 1.2)).norm() < 1e-12, "{t}");
    assert!((s.tracker_from_marker.rotation.angle() - std::f64::consts::FRAC_PI_4).abs() < 1e-9);
    // The stamp maps onto our clock: after we asked, before now.
    let now = clock.now_s();
    assert!(
        (asked..=now).contains(&s.acquired_s),
        "acquired {} not within [{asked}, {now}]",
        s.acquired_s
    );
}
