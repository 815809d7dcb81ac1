#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! Interop: SDU's `ur-rtde` 1.6.5 (the PyPI wheel) drives our simulated controller, unchanged,
//! on the standard UR ports of its own loopback address (ur_rtde cannot change ports).
//! A missing peer fails the test with install instructions.

use mocomp_kin::{Arm, Model};
use mocomp_testkit::PythonPeer;
use mocomp_ursim::{ControllerConfig, Sim, SimConfig};
use serde_json::{Value, json};
use std::net::IpAddr;

const VERSION: &str = "1.6.5";

fn peer() -> PythonPeer {
    PythonPeer::start("ur_rtde_peer.py", "ur-rtde", VERSION)
}

fn sim_at(model: Model, host: &str) -> Sim {
    let host: IpAddr = host.parse().unwrap();
    Sim::start(SimConfig::new(ControllerConfig::new(model), host)).unwrap()
}

fn vec6(v: &Value) -> [f64; 6] {
    let a = v.as_array().unwrap();
    std::array::from_fn(|i| a[i].as_f64().unwrap())
}

fn check_receive(model: Model, host: &str, rate: f64) {
    let sim = sim_at(model, host);
    // A wrench on the tool (a contact): ur_rtde's getActualTCPForce reads what our client reads.
    let wrench = [1.5, -2.25, 18.0, 0.125, -0.5, 0.0625];
    sim.with(|c| c.set_tcp_force(wrench));
    let mut p = peer();
    let r = p.request(&json!({"op": "receive", "host": host, "seconds": 1.0}));
    let distinct = r["distinct"].as_f64().unwrap();
    let span = r["last_ts"].as_f64().unwrap() - r["first_ts"].as_f64().unwrap();
    eprintln!(
        "{model}: ur_rtde saw {distinct} distinct timestamps in 1 s ({rate} Hz expected), span {span:.3} s"
    );
    // Every package is one controller cycle: the smallest step between the timestamps ur_rtde
    // saw is one period (a stream at a lower rate could not show it). How many of them the
    // peer's Python polling catches depends on how busy the machine is, so their count is only
    // bounded loosely: more than a quarter-rate stream could give, and no more than the
    // controller sends (plus, at most, the 25 ms of cycles a delayed simulator makes up).
    let min_step = r["min_step"].as_f64().unwrap();
    assert!(
        (min_step - 1.0 / rate).abs() < 1e-6,
        "smallest step {min_step} s"
    );
    assert!(
        distinct > 0.3 * rate && distinct <= 1.025 * rate + 3.0,
        "{distinct}"
    );
    assert!(span > 0.7 && span < 1.05, "timestamps span {span} s");
    let q = vec6(&r["actual_q"]);
    let sim_q = sim.with(|c| c.q());
    assert_eq!(q, sim_q, "a robot at rest reports its joints exactly");
    assert_eq!(vec6(&r["target_q"]), sim_q);
    let tcp = vec6(&r["tcp"]);
    let fk = mocomp_geom::ur_pose_from_iso(&Arm::new(model).fk(&sim_q));
    for i in 0..6 {
        assert!((tcp[i] - fk[i]).abs() < 1e-12, "TCP pose {i}");
    }
    assert_eq!(
        vec6(&r["tcp_force"]),
        wrench,
        "actual_TCP_force as ur_rtde reads it"
    );
    let mut ours = mocomp_ur::UrRobot::connect(
        sim.ur_config(),
        std::sync::Arc::new(mocomp_geom::MonotonicClock::new()),
    )
    .unwrap();
    mocomp_testkit::wait_until("our client's state", || {
        mocomp_ur::Robot::keep_alive(&mut ours).unwrap();
        mocomp_ur::Robot::state(&ours).is_some()
    });
    let s = mocomp_ur::Robot::state(&ours).unwrap();
    assert_eq!(s.tcp_force, wrench, "the same wrench through our client");
    assert_eq!(r["robot_mode"], 7);
    assert_eq!(r["safety_mode"], 1);
    assert_eq!(r["joint_mode"][0], 253);
    assert_eq!(r["speed_scaling"], 1.0);
    assert_eq!(r["protective_stopped"], false);
}

#[test]
fn receive_interface_gets_e_series_data_at_500_hz() {
    check_receive(Model::Ur5e, "127.0.77.2", 500.0);
}

#[test]
fn receive_interface_gets_cb3_data_at_125_hz() {
    check_receive(Model::Ur5, "127.0.77.3", 125.0);
}

#[test]
fn control_interface_moves_the_simulated_joints() {
    let host = "127.0.77.4";
    let sim = sim_at(Model::Ur3e, host);
    let mut p = peer();
    let c = p.request(&json!({"op": "control_connect", "host": host}));
    eprintln!(
        "ur_rtde RTDEControlInterface connected in {:.1} ms",
        c["connect_ms"]
    );
    let q0 = vec6(&c["q"]);

    // zeroFtSensor: the sensor's present reading (a bias) becomes its zero.
    let bias = [0.75, -1.5, 6.25, 0.0, 0.125, 0.0];
    sim.with(|c| c.set_tcp_force(bias));
    let z = p.request(&json!({"op": "zeroFtSensor"}));
    assert_eq!(z["ok"], true, "{z}");
    assert_eq!(vec6(&z["before"]), bias, "{z}");
    assert_eq!(vec6(&z["after"]), [0.0; 6], "{z}");

    // moveJ (blocking): returns when done, at the goal.
    let mut goal = q0;
    goal[0] += 0.3;
    goal[3] -= 0.2;
    let r = p.request(&json!({"op": "moveJ", "q": goal, "speed": 1.0, "acc": 3.0}));
    assert_eq!(r["ok"], true);
    let q = sim.with(|c| c.q());
    for j in 0..6 {
        assert!(
            (q[j] - goal[j]).abs() < 1e-9,
            "moveJ joint {j}: {} vs {}",
            q[j],
            goal[j]
        );
    }

    // servoJ streamed at 500 Hz for 2 s: the joints follow the trajectory.
    let r = p.request(
        &json!({"op": "servo_stream", "seconds": 2.0, "amplitude": 0.1,
                              "lookahead": 0.1, "gain": 300}),
    );
    eprintln!(
        "ur_rtde servoJ: period median {:.3} ms, p99 {:.3} ms, call median {:.1} us, \
         max tracking error {:.4} rad",
        r["period_median_ms"], r["period_p99_ms"], r["call_median_us"], r["max_err"]
    );
    let target = vec6(&r["final_target"]);
    let actual = vec6(&r["final_actual"]);
    let sim_q = sim.with(|c| c.q());
    for j in 0..6 {
        // After servoStop the arm stops within its lag of the last target.
        assert!((actual[j] - target[j]).abs() < 0.05, "joint {j}");
        assert!((sim_q[j] - actual[j]).abs() < 1e-9);
    }
    assert!(
        (sim_q[0] - goal[0]).abs() > 0.01,
        "the servo stream moved joint 1"
    );
    // The lag of a servo with lookahead 0.1 s following ≤ 0.3 rad/s is about 0.03 rad.
    let max_err = r["max_err"].as_f64().unwrap();
    assert!(max_err < 0.06 && max_err > 0.001, "{max_err}");

    // speedJ, then speedStop.
    let r = p.request(
        &json!({"op": "speedJ", "qd": [0.0, 0.0, 0.0, 0.0, 0.0, 0.4], "acc": 4.0,
                              "seconds": 0.4}),
    );
    assert_eq!(r["ok"], true);
    let qd = vec6(&r["qd"]);
    assert!((qd[5] - 0.4).abs() < 1e-9, "speedJ {qd:?}");
    let r = p.request(&json!({"op": "speedStop", "acc": 10.0}));
    let q_stopped = vec6(&r["q"]);
    assert_eq!(sim.with(|c| c.qd()), [0.0; 6]);

    // stopJ at rest, then stopScript.
    let r = p.request(&json!({"op": "stopJ", "acc": 2.0}));
    assert_eq!(vec6(&r["q"]), q_stopped);
    let r = p.request(&json!({"op": "stopScript"}));
    assert_eq!(r["runtime_state"], 1, "STOPPED");
    assert_eq!(sim.with(|c| c.protective_stops()), 0);
    let (events, _) = sim.with(|c| c.events());
    assert!(
        events
            .iter()
            .any(|e| e.text.contains("ur_rtde control script started"))
    );
    p.request(&json!({"op": "disconnect"}));
}
