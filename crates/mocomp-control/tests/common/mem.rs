//! An in-memory world for the loop's tests and benchmark: a robot that is wherever it was last
//! commanded (its state's times and faults set by the test), and a 60 Hz tracker of a nodding,
//! noisy head, 20 ms old. No sockets, no threads, no clock: time is what the test says.
#![allow(dead_code, clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_control::{Compensator, CycleRecord, Event, HeadModel, LoopConfig, Mode};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_geom::{PoseSample, PoseSource};
use mocomp_kin::{Arm, Model, Selection};
pub use mocomp_testkit::mem::MemRobot;

use mocomp_testkit::scene::{base_from_tracker, flange_from_coil, head_from_coil_goal, head_rest};

pub const PERIOD: f64 = 0.002;

fn base_from_head(t: f64) -> Isometry3<f64> {
    // From rest, after the loop's start-up hold.
    let s = (4.0 * (t - 0.5).max(0.0)).sin();
    head_rest()
        * Isometry3::new(
            Vector3::new(0.02 * s, 0.01 * s, 0.0),
            Vector3::new(0.0, 0.05 * s, 0.15 * s),
        )
}

/// The UR3e's joints with the coil at its goal on the head at rest.
pub fn coil_on_head_joints(arm: &Arm) -> [f64; 6] {
    let start = head_rest() * head_from_coil_goal() * flange_from_coil().inverse();
    arm.ik_closest(
        &start,
        &[0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
        &Selection::tracking(0.05),
    )
    .unwrap()
    .joints
}

/// 60 Hz samples of the nodding head with 0.1 mm of deterministic noise, 20 ms old.
pub struct MemTracker {
    /// Loop time, s.
    pub now: f64,
    /// Added to every acquisition time: a sender's clock mapped wrong (it stepped), s.
    pub stamp_offset_s: f64,
    k: u64,
    x: u64,
}

impl PoseSource for MemTracker {
    fn latest(&mut self) -> Option<PoseSample> {
        let t = self.k as f64 / 60.0;
        if t + 0.02 > self.now {
            return None;
        }
        self.k += 1;
        self.x = self.x.wrapping_mul(6364136223846793005).wrapping_add(1);
        let n = ((self.x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 3.5e-4;
        let mut pose = base_from_tracker().inverse() * base_from_head(t);
        pose.translation.vector += Vector3::new(n, -n, 0.5 * n);
        Some(PoseSample {
            tracker_from_marker: pose,
            acquired_s: t + self.stamp_offset_s,
            valid: true,
            error_m: f64::NAN,
        })
    }
}

pub struct World {
    /// The loop.
    pub comp: Compensator,
    /// The robot.
    pub robot: MemRobot,
    /// The tracker.
    pub tracker: MemTracker,
}

impl World {
    /// At rest, past the start-up hold, tracking.
    pub fn new() -> Self {
        Self::with_head(HeadModel::adult())
    }

    /// [`Self::new`] with `head` as the loop's head model.
    pub fn with_head(head: HeadModel) -> Self {
        Self::with_config(head, |_| {})
    }

    /// [`Self::with_head`], the loop's configuration changed by `change` first.
    pub fn with_config(head: HeadModel, change: impl FnOnce(&mut LoopConfig)) -> Self {
        let arm = Arm::new(Model::Ur3e);
        let flange_from_coil = flange_from_coil();
        let q0 = coil_on_head_joints(&arm);
        let mut cfg = LoopConfig::new(
            base_from_tracker(),
            flange_from_coil,
            head_from_coil_goal(),
            PERIOD,
        );
        cfg.head = head;
        change(&mut cfg);
        let mut w = Self {
            comp: Compensator::new(cfg, arm, PERIOD),
            robot: MemRobot::at(q0, arm.fk(&q0), PERIOD),
            tracker: MemTracker {
                now: 0.0,
                stamp_offset_s: 0.0,
                k: 0,
                x: 42,
            },
        };
        // Past the start-up hold, into tracking.
        for _ in 0..1000 {
            w.cycle();
        }
        assert_eq!(w.comp.mode(), Mode::Tracking, "{:?}", w.comp.mode());
        w
    }

    /// One cycle on time: a fresh state one period after the last.
    pub fn cycle(&mut self) -> Mode {
        self.cycle_record().mode
    }

    /// [`Self::cycle`], its record.
    pub fn cycle_record(&mut self) -> CycleRecord {
        let now = self.tracker.now;
        self.robot.state.received_s = now;
        self.robot.state.controller_s = now;
        let rec = self.comp.cycle(now, &mut self.robot, &mut self.tracker);
        self.tracker.now += PERIOD;
        rec
    }

    /// `n` cycles on time (a fresh state each); the modes and events they ended with.
    pub fn run(&mut self, n: usize) -> Vec<(Mode, Option<Event>)> {
        (0..n)
            .map(|_| {
                let now = self.tracker.now;
                self.robot.state.received_s = now;
                self.robot.state.controller_s = now;
                let r = self.cycle_at(now);
                self.tracker.now += PERIOD;
                (r.mode, r.event)
            })
            .collect()
    }

    /// One cycle at loop time `now` on whatever state the test set up.
    pub fn cycle_at(&mut self, now: f64) -> CycleRecord {
        self.tracker.now = now;
        self.comp.cycle(now, &mut self.robot, &mut self.tracker)
    }
}
