//! Benchmarks: the RTDE codec (our client's state package decode and command encode, the
//! simulator's state package encode) and a full state-to-command round trip on loopback
//! (simulator cycle → state package → client thread → `servo` command → simulator), on a stepped
//! clock so the controller period does not enter the figure.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // bench code

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_geom::MonotonicClock;
use mocomp_kin::Model;
use mocomp_ur::client::STATE_NAMES;
use mocomp_ur::codec::{Direction, FrameDecoder, Recipe, Reply, decode_reply};
use mocomp_ur::program::INPUT_NAMES;
use mocomp_ur::{Robot, ServoParams, UrRobot, Value};
use mocomp_ursim::{ControllerConfig, Sim, SimConfig};
use std::hint::black_box;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// ur_rtde's default receive recipe (37 variables, 1,000+ bytes per package).
const UR_RTDE_DEFAULT: [&str; 37] = [
    "timestamp",
    "target_q",
    "target_qd",
    "target_qdd",
    "target_current",
    "target_moment",
    "actual_q",
    "actual_qd",
    "actual_current",
    "joint_control_output",
    "actual_TCP_pose",
    "actual_TCP_speed",
    "actual_TCP_force",
    "target_TCP_pose",
    "target_TCP_speed",
    "actual_digital_input_bits",
    "joint_temperatures",
    "actual_execution_time",
    "robot_mode",
    "joint_mode",
    "safety_mode",
    "actual_tool_accelerometer",
    "speed_scaling",
    "target_speed_fraction",
    "actual_momentum",
    "actual_main_voltage",
    "actual_robot_voltage",
    "actual_robot_current",
    "actual_joint_voltage",
    "actual_digital_output_bits",
    "runtime_state",
    "standard_analog_input0",
    "standard_analog_input1",
    "standard_analog_output0",
    "standard_analog_output1",
    "robot_status_bits",
    "safety_status_bits",
];

fn codec(c: &mut Criterion) {
    let sim_ctrl = mocomp_ursim::Controller::new(ControllerConfig::new(Model::Ur5e));
    for (name, names) in [
        ("ours", &STATE_NAMES[..]),
        ("ur_rtde_default_37", &UR_RTDE_DEFAULT[..]),
    ] {
        let recipe = Recipe::from_table(1, names, Direction::Output).unwrap();
        let vars: Vec<_> = names
            .iter()
            .map(|n| mocomp_ursim::controller::OutputVar::resolve(n).unwrap().0)
            .collect();
        let values: Vec<Value> = vars.iter().map(|v| sim_ctrl.output(*v)).collect();
        let mut bytes = Vec::new();
        recipe
            .encode_output_package(&values, 2, &mut bytes)
            .unwrap();
        c.bench_function(&format!("rtde/encode_state/{name}"), |b| {
            let mut out = Vec::with_capacity(2048);
            b.iter(|| {
                out.clear();
                recipe
                    .encode_output_package(black_box(&values), 2, &mut out)
                    .unwrap();
                out.len()
            })
        });
        c.bench_function(&format!("rtde/decode_state/{name}"), |b| {
            let mut dec = FrameDecoder::new();
            let mut vals = Vec::with_capacity(64);
            b.iter(|| {
                dec.push(black_box(&bytes));
                let f = dec.next_frame().unwrap().unwrap();
                let Ok(Reply::Data { payload, .. }) = decode_reply(f.kind, f.payload, 2) else {
                    panic!("not data")
                };
                recipe.unpack(payload, &mut vals).unwrap();
                vals.len()
            })
        });
    }
    let input = Recipe::from_table(1, &INPUT_NAMES, Direction::Input).unwrap();
    let mut values = vec![Value::Int32(1), Value::Int32(7)];
    values.extend((0..9).map(|i| Value::Double(f64::from(i) * 0.1)));
    c.bench_function("rtde/encode_command", |b| {
        let mut out = Vec::with_capacity(128);
        b.iter(|| {
            out.clear();
            input
                .encode_input_package(black_box(&values), &mut out)
                .unwrap();
            out.len()
        })
    });
}

fn round_trip(c: &mut Criterion) {
    let sim = Sim::start(SimConfig::stepped_local(ControllerConfig::new(Model::Ur5e))).unwrap();
    let mut cfg = sim.ur_config();
    cfg.watchdog_hz = 1.0;
    let done = AtomicBool::new(false);
    let mut robot = std::thread::scope(|s| {
        s.spawn(|| {
            while !done.load(Ordering::Relaxed) {
                sim.step();
                std::thread::sleep(Duration::from_micros(500));
            }
        });
        let r = UrRobot::connect(cfg, Arc::new(MonotonicClock::new())).unwrap();
        done.store(true, Ordering::Relaxed);
        r
    });
    let q = robot.state().unwrap().actual_q;
    let p = ServoParams::for_period(0.002);
    c.bench_function("loopback/state_to_command_round_trip", |b| {
        b.iter(|| {
            let n_state = robot.state_count();
            let n_in = sim.stats().inputs;
            sim.step();
            while robot.state_count() == n_state {
                std::hint::spin_loop();
            }
            let s = robot.state().unwrap();
            robot.servo(black_box(&q), &p).unwrap();
            while sim.stats().inputs == n_in {
                std::hint::spin_loop();
            }
            s.controller_s
        })
    });
}

criterion_group!(benches, codec, round_trip);
criterion_main!(benches);
