//! An in-memory robot and pose source, for testing the compensation loop's rules and filter
//! without sockets, threads or clocks: time is whatever the test says.

use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, MonotonicClock, PoseSample, PoseSource};
use mocomp_robot::{Robot, RobotError, RobotState, ServoParams};
use std::sync::atomic::{AtomicU64, Ordering};

/// The machine's monotonic clock, except that its `n`-th reading panics (once): a fault injected
/// into a thread that reads the clock for every message it handles (a reader, a worker), through
/// the clock it is given and nothing else.
#[derive(Debug)]
pub struct PanicsOnce {
    n: u64,
    calls: AtomicU64,
    inner: MonotonicClock,
}

impl PanicsOnce {
    /// Panics on the `n`-th reading (from 1).
    pub fn on_reading(n: u64) -> Self {
        Self {
            n,
            calls: AtomicU64::new(0),
            inner: MonotonicClock::new(),
        }
    }
}

impl Clock for PanicsOnce {
    fn now_s(&self) -> f64 {
        let k = self.calls.fetch_add(1, Ordering::Relaxed) + 1;
        assert!(k != self.n, "injected fault on reading {}", self.n);
        self.inner.now_s()
    }
}

/// A robot that is wherever it was last commanded (a perfect servo), healthy, its state's times
/// and faults set by the test through [`MemRobot::state`].
#[derive(Debug, Clone)]
pub struct MemRobot {
    /// What it reports (tests change times, speeds and faults).
    pub state: RobotState,
    /// The controller period it reports, s.
    pub period_s: f64,
    /// Commands taken (the last one's sequence number).
    pub seq: i32,
    /// `stop` calls.
    pub stops: u32,
    /// The last movej target taken.
    pub last_move: Option<[f64; 6]>,
    /// `keep_alive` calls.
    pub keep_alives: u32,
    /// `freedrive` calls (a hand moves the arm: tests set its joints).
    pub freedrives: u32,
}

impl MemRobot {
    /// A healthy robot at rest at `q`, whose flange is `base_from_tcp`, with `period_s`.
    pub fn at(q: [f64; 6], base_from_tcp: Isometry3<f64>, period_s: f64) -> Self {
        Self {
            state: RobotState::at_rest(0.0, q, base_from_tcp),
            period_s,
            seq: 0,
            stops: 0,
            last_move: None,
            keep_alives: 0,
            freedrives: 0,
        }
    }

    /// A fresh state at `t` (controller and receive time alike), as a robot on time sends.
    pub fn tick(&mut self, t: f64) {
        self.state.controller_s = t;
        self.state.received_s = t;
    }
}

impl Robot for MemRobot {
    fn state(&self) -> Option<RobotState> {
        Some(self.state)
    }
    fn state_count(&self) -> u64 {
        u64::try_from(self.seq).unwrap_or(0)
    }
    fn period_s(&self) -> f64 {
        self.period_s
    }
    fn servo(&mut self, q: &[f64; 6], _: &ServoParams) -> Result<i32, RobotError> {
        self.seq += 1;
        self.state.actual_q = *q;
        self.state.target_q = *q;
        self.state.acked_seq = self.seq;
        Ok(self.seq)
    }
    fn move_joints(&mut self, q: &[f64; 6], _: f64, _: f64) -> Result<i32, RobotError> {
        self.seq += 1;
        self.last_move = Some(*q);
        Ok(self.seq)
    }
    fn speed_joints(&mut self, _: &[f64; 6], _: f64) -> Result<i32, RobotError> {
        Ok(self.seq)
    }
    fn stop(&mut self, _: f64) -> Result<i32, RobotError> {
        // A command of its own, taken at once (a test that plays a slow controller sets
        // `state.acked_seq` back).
        self.stops += 1;
        self.seq += 1;
        self.state.acked_seq = self.seq;
        Ok(self.seq)
    }
    fn keep_alive(&mut self) -> Result<(), RobotError> {
        self.keep_alives += 1;
        Ok(())
    }
    fn freedrive(&mut self) -> Result<i32, RobotError> {
        self.seq += 1;
        self.freedrives += 1;
        self.state.acked_seq = self.seq;
        Ok(self.seq)
    }
}

/// The marker pose at a time, or `None` while it is out of view.
pub type Truth = Box<dyn Fn(f64) -> Option<Isometry3<f64>>>;

/// A tracker sampling `truth` at `rate_hz`, each sample available `latency_s` after its
/// acquisition; a sample out of view is sent as invalid, as trackers do.
pub struct ScriptedPoses {
    /// Now, s (the test advances it).
    pub now: f64,
    /// Samples per second.
    pub rate_hz: f64,
    /// Acquisition to availability, s.
    pub latency_s: f64,
    /// While set, samples are lost (a tracker whose reader stopped).
    pub silent: bool,
    /// What [`PoseSource::failures`] reports (a reader thread's failures, set by the test).
    pub failures: u64,
    truth: Truth,
    k: u64,
}

impl std::fmt::Debug for ScriptedPoses {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ScriptedPoses")
            .field("now", &self.now)
            .field("rate_hz", &self.rate_hz)
            .field("latency_s", &self.latency_s)
            .finish_non_exhaustive()
    }
}

impl ScriptedPoses {
    /// A tracker of `truth` from t = 0.
    pub fn new(rate_hz: f64, latency_s: f64, truth: Truth) -> Self {
        Self {
            now: 0.0,
            rate_hz,
            latency_s,
            silent: false,
            failures: 0,
            truth,
            k: 0,
        }
    }
}

impl PoseSource for ScriptedPoses {
    fn latest(&mut self) -> Option<PoseSample> {
        let mut newest = None;
        loop {
            let t = self.k as f64 / self.rate_hz;
            if t + self.latency_s > self.now {
                return newest;
            }
            self.k += 1;
            if self.silent {
                continue;
            }
            newest = Some(match (self.truth)(t) {
                Some(pose) => PoseSample {
                    tracker_from_marker: pose,
                    acquired_s: t,
                    valid: true,
                    error_m: f64::NAN,
                },
                None => PoseSample {
                    tracker_from_marker: Isometry3::identity(),
                    acquired_s: t,
                    valid: false,
                    error_m: f64::NAN,
                },
            });
        }
    }

    fn failures(&self) -> u64 {
        self.failures
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Vector3;

    #[test]
    fn samples_come_after_their_latency_newest_first_and_out_of_view_as_invalid() {
        let mut s = ScriptedPoses::new(
            10.0,
            0.05,
            Box::new(|t| (t < 0.25).then(|| Isometry3::translation(t, 0.0, 0.0))),
        );
        assert!(s.latest().is_none());
        s.now = 0.26;
        // Acquired at 0.0, 0.1, 0.2 (0.2 + 0.05 ≤ 0.26): the newest is returned.
        let p = s.latest().unwrap();
        assert_eq!(p.acquired_s, 0.2);
        assert!(p.valid);
        assert_eq!(
            p.tracker_from_marker.translation.vector,
            Vector3::new(0.2, 0.0, 0.0)
        );
        assert!(s.latest().is_none());
        s.now = 0.36;
        let p = s.latest().unwrap();
        assert!(!p.valid, "out of view at 0.3");
    }

    #[test]
    fn the_robot_is_where_it_was_commanded() {
        let mut r = MemRobot::at([0.1; 6], Isometry3::identity(), 0.002);
        let q = [0.2, 0.1, 0.0, -0.1, 0.3, 0.4];
        let seq = r.servo(&q, &ServoParams::for_period(0.002)).unwrap();
        let s = r.state().unwrap();
        assert_eq!(s.actual_q, q);
        assert_eq!(s.acked_seq, seq);
        r.tick(1.5);
        assert_eq!(r.state().unwrap().received_s, 1.5);
        r.stop(4.0).unwrap();
        assert_eq!(r.stops, 1);
    }
}
