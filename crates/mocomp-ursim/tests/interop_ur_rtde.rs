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
    // saw is one period (a stream at a lower rate could not show it). How many the peer's
    // Python polling catches depends on how busy the machine is; what holds on any machine is
    // that it never sees more cycles than the span of controller time it saw holds, and that
    // the controller's time did not run ahead of the 1 s the peer listened (plus the 25 ms of
    // cycles a delayed simulator makes up).
    let min_step = r["min_step"].as_f64().unwrap();
    assert!(
        (min_step - 1.0 / rate).abs() < 1e-6,
        "smallest step {min_step} s"
    );
    assert!(
        distinct >= 2.0 && distinct <= (span * rate).round() + 1.0,
        "{distinct} distinct in {span} s"
    );
    assert!(
        span > 0.0 && span < 1.025 + 2.0 / rate,
        "timestamps span {span} s"
    );
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
fn io_interface_sets_digital_outputs_that_read_back_and_reads_the_inputs() {
    let host = "127.0.77.9";
    let sim = sim_at(Model::Ur5e, host);
    // The world drives standard input 3 (a stimulator's trigger line).
    sim.with(|c| c.set_digital_input(3, true));
    let mut p = peer();
    let r = p.request(&json!({"op": "io", "host": host}));
    eprintln!("ur_rtde RTDEIOInterface: {r}");
    // ur_rtde's io_example.py: output 7 high, read back high; then low again.
    assert_eq!(r["set_high"], true, "{r}");
    assert_eq!(r["out7_high"], true, "{r}");
    assert_eq!(
        r["conf2_high"], true,
        "configurable output 2 is bit 10: {r}"
    );
    assert_eq!(r["out7_low"], true, "{r}");
    assert_eq!(r["bits"], 1 << 10, "{r}");
    assert_eq!(r["in_bits"], 1 << 3, "{r}");
    assert_eq!(r["in3"], true, "{r}");
    // The controller holds what the client set.
    assert_eq!(sim.with(|c| c.io().digital_outputs()), 1 << 10);
}

#[test]
fn a_command_the_simulator_does_not_emulate_is_refused_not_faked() {
    let host = "127.0.77.15";
    let sim = sim_at(Model::Ur5e, host);
    let mut p = peer();
    p.request(&json!({"op": "control_connect", "host": host}));
    let q = sim.with(|c| c.q());
    let r = p.request(&json!({"op": "teachMode"}));
    eprintln!("ur_rtde teachMode against the simulator: {r}");
    assert_eq!(r["ok"], false, "{r}");
    let events = sim.with(|c| c.event_texts());
    assert!(
        events
            .iter()
            .any(|e| e.contains("is not emulated by this simulator")),
        "{events:?}"
    );
    assert_eq!(
        sim.with(|c| c.runtime_state()),
        mocomp_ur::RuntimeState::Stopped
    );
    assert_eq!(sim.with(|c| c.q()), q, "nothing moved");
}

#[test]
fn control_interface_moves_the_simulated_joints() {
    let host = "127.0.77.14";
    let sim = sim_at(Model::Ur3e, host);
    let mut p = peer();
    let c = p.request(&json!({"op": "control_connect", "host": host}));
    eprintln!(
        "ur_rtde RTDEControlInterface connected in {:.1} ms",
        c["connect_ms"]
    );
    let q0 = vec6(&c["q"]);

    // moveL: the TCP on a straight line to the target (sampled on the way by ur_rtde's receive
    // interface), and there at the end.
    let m = p.request(
        &json!({"op": "moveL", "offset": [0.04, -0.03, 0.02, 0.0, 0.0, 0.0],
                              "speed": 0.1, "acc": 0.5}),
    );
    assert_eq!(m["ok"], true, "{m}");
    let (start, target) = (vec6(&m["start"]), vec6(&m["target"]));
    let line = mocomp_geom::nalgebra::Vector3::new(
        target[0] - start[0],
        target[1] - start[1],
        target[2] - start[2],
    );
    let path = m["path"].as_array().unwrap();
    assert!(path.len() > 20, "{} samples", path.len());
    let off_line = path
        .iter()
        .map(|p| {
            let a = p.as_array().unwrap();
            let d = mocomp_geom::nalgebra::Vector3::new(
                a[0].as_f64().unwrap() - start[0],
                a[1].as_f64().unwrap() - start[1],
                a[2].as_f64().unwrap() - start[2],
            );
            (d - line * (d.dot(&line) / line.norm_squared())).norm()
        })
        .fold(0.0f64, f64::max);
    assert!(off_line < 1e-6, "the TCP left the line by {off_line} m");
    let fin = vec6(&m["final"]);
    for i in 0..6 {
        assert!(
            (fin[i] - target[i]).abs() < 1e-6,
            "final {fin:?} vs {target:?}"
        );
    }

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
