#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! The cycle allocates nothing: a counting global allocator (allocation-counter) counts the
//! allocations made on the loop's thread while `Compensator::cycle` runs, with the real client (`UrRobot`) talking to a
//! stepped simulator over TCP, and a tracker source that nods the head with noise and dropouts.

mod common;

use mocomp_control::{Compensator, LoopConfig, Mode};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_geom::{Clock, PoseSample, PoseSource, SteppedClock};
use mocomp_kin::{Arm, Model};
use mocomp_testkit::{SplitMix64, spin_until};
use mocomp_ur::{Robot, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimConfig, ToolLoad};
use std::sync::Arc;

/// Runs `f`, counting the allocations it makes on this thread (`allocation-counter` replaces
/// the global allocator in this test binary).
fn counted<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let mut out = None;
    let info = allocation_counter::measure(|| out = Some(f()));
    (out.unwrap(), info.count_total)
}

use mocomp_testkit::scene::{base_from_tracker, flange_from_coil, head_from_coil_goal, head_rest};

const PERIOD: f64 = 0.002;

fn base_from_head(t: f64) -> Isometry3<f64> {
    let s = (4.0 * t).sin();
    // The head moved 30 mm while out of view (from 1.1 s): the loop comes back by a path.
    let moved = if t >= 1.1 { 0.03 } else { 0.0 };
    head_rest()
        * Isometry3::new(
            Vector3::new(0.01 * s + moved, 0.005 * s, 0.0),
            Vector3::new(0.0, 0.04 * s, 0.08 * s),
        )
}

/// 60 Hz, 20 ms latency, 0.1 mm noise, a 300 ms dropout at 1 s (the head moves meanwhile), an
/// outlier at 1.5 s.
struct NoddingTracker {
    clock: Arc<SteppedClock>,
    k: u64,
    rng: SplitMix64,
}

impl PoseSource for NoddingTracker {
    fn latest(&mut self) -> Option<PoseSample> {
        let mut newest = None;
        loop {
            let t = self.k as f64 / 60.0;
            if t + 0.02 > self.clock.now_s() {
                return newest;
            }
            self.k += 1;
            if (1.0..1.3).contains(&t) {
                continue;
            }
            let mut pose = base_from_tracker().inverse() * base_from_head(t);
            let mut n = || (self.rng.next_f64() - 0.5) * 3.5e-4;
            pose.translation.vector += Vector3::new(n(), n(), n());
            if (t - 1.5).abs() < 0.008 {
                pose.translation.vector.x += 0.05;
            }
            newest = Some(PoseSample {
                tracker_from_marker: pose,
                acquired_s: t,
                valid: true,
                error_m: f64::NAN,
            });
        }
    }
}

#[test]
fn the_cycle_allocates_nothing() {
    let arm = Arm::new(Model::Ur3e);
    let flange_from_coil = flange_from_coil();
    let q0 = common::mem::coil_on_head_joints(&arm);
    let mut ctrl = ControllerConfig::new(Model::Ur3e);
    ctrl.initial_q = q0;
    // A live force sensor's noise (a few tenths of a newton), so the force rules run.
    let mut k = 0u64;
    ctrl.tool_load = Some(ToolLoad::new(move |_, _| {
        k += 1;
        let n = |m: u64| ((k * m) % 17) as f64 * 0.02 - 0.16;
        [n(7919), n(104_729), n(1_299_709), 0.0, 0.0, 0.0]
    }));
    let sim = Sim::start(SimConfig::stepped_local(ctrl)).unwrap();
    let clock = Arc::new(SteppedClock::new(0.0));
    let ucfg = sim.ur_config();
    let mut robot = sim
        .stepping_in_real_time(|| UrRobot::connect(ucfg, clock.clone()))
        .unwrap();
    let mut cfg = LoopConfig::new(
        base_from_tracker(),
        flange_from_coil,
        head_from_coil_goal(),
        PERIOD,
    );
    cfg.params.force_sensing = true;
    let mut comp = Compensator::new(cfg, arm, PERIOD);
    let mut tracker = NoddingTracker {
        clock: Arc::clone(&clock),
        k: 0,
        rng: SplitMix64(7),
    };
    let n = robot.state_count();
    robot.keep_alive().unwrap();
    sim.step();
    spin_until("first state", || robot.state_count() > n);
    let (mut allocations, mut tracking, mut holding, mut events) = (0, 0, 0, 0);
    let (mut approaching, mut forces) = (0, 0);
    for _ in 0..1500 {
        let inputs = sim.stats().inputs;
        let now = clock.now_s();
        let (rec, count) = counted(|| comp.cycle(now, &mut robot, &mut tracker));
        allocations += count;
        match rec.mode {
            Mode::Tracking => tracking += 1,
            Mode::Holding(_) => holding += 1,
            Mode::Approaching => approaching += 1,
            _ => {}
        }
        events += usize::from(rec.event.is_some());
        forces += usize::from(rec.contact_force_n.is_finite());
        spin_until("command", || sim.stats().inputs > inputs);
        let states = robot.state_count();
        clock.advance(PERIOD);
        sim.step();
        spin_until("state", || robot.state_count() > states);
    }
    // The run went through tracking, coasting, holds (start-up, the dropout past the coast
    // time), a planned path back and events (resume, coasting, outlier).
    assert!(tracking > 400, "{tracking} tracking");
    assert!(approaching > 100, "{approaching} approaching");
    assert!(holding > 100, "{holding}");
    assert!(events >= 4, "{events}");
    assert!(forces > 1000, "the force rules ran in {forces} cycles");
    assert_eq!(allocations, 0, "allocations in 1500 cycles");
    // The counter works.
    let (_, c) = counted(|| vec![1u8; 10]);
    assert_eq!(c, 1);
}
