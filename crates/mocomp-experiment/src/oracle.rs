//! The oracle: the head's true motion over a whole run, known in advance, for a controller that
//! knows the future and has no latency ([`mocomp_control::Compensator::with_head_oracle`]). Its
//! error is the least any controller could make on this coil robot; the others' excess over it
//! is what better prediction or servoing could still win.
//!
//! The truth is the head robot's own joints, tick by tick, from a pass that plays the motion
//! with the coil robot standing still: the head robot's run does not depend on the coil's, so the
//! oracle's run then meets exactly this head. Between ticks the joints are interpolated as the
//! simulated tracker does, so the oracle and the tracker see one head.
//!
//! Pure: no I/O, no clock (the experiment records the truth and says when the run started).

use mocomp_control::HeadOracle;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, PoseSample, PoseSource};
use mocomp_kin::Arm;
use std::sync::Arc;

/// The head robot's joints at every tick of a run, and how they put the head in the tracker.
#[derive(Debug, Clone)]
pub struct HeadTruth {
    arm: Arm,
    /// The tracker's view of the head robot's base.
    tracker_from_base: Isometry3<f64>,
    e2_from_head: Isometry3<f64>,
    period_s: f64,
    /// Joints at 0, 1, 2, … periods after the run's start.
    q: Vec<[f64; 6]>,
}

impl HeadTruth {
    /// The truth from the joints `q` at every `period_s` from the run's start.
    pub fn new(
        arm: Arm,
        tracker_from_base: Isometry3<f64>,
        e2_from_head: Isometry3<f64>,
        period_s: f64,
        q: Vec<[f64; 6]>,
    ) -> Self {
        Self {
            arm,
            tracker_from_base,
            e2_from_head,
            period_s,
            q,
        }
    }

    /// The head robot's joints at run time `t_s`, linear between ticks, held beyond the ends.
    pub fn joints_at(&self, t_s: f64) -> Option<[f64; 6]> {
        let last = self.q.len().checked_sub(1)?;
        let x = (t_s / self.period_s).clamp(0.0, last as f64);
        let k = (x.floor() as usize).min(last.saturating_sub(1));
        let s = x - k as f64;
        let (a, b) = (self.q[k], self.q[(k + 1).min(last)]);
        Some(std::array::from_fn(|j| a[j] + (b[j] - a[j]) * s))
    }

    /// `tracker_from_head` at run time `t_s`.
    pub fn at(&self, t_s: f64) -> Option<Isometry3<f64>> {
        self.joints_at(t_s)
            .map(|q| self.tracker_from_base * self.arm.fk_flange(&q) * self.e2_from_head)
    }

    /// How long the truth reaches, s from the run's start.
    pub fn span_s(&self) -> f64 {
        self.q.len().saturating_sub(1) as f64 * self.period_s
    }
}

/// [`HeadTruth`] on the loop's clock: the run started at `t0`.
#[derive(Debug, Clone)]
pub struct TruthOracle {
    /// The truth.
    pub truth: Arc<HeadTruth>,
    /// The loop's clock at the run's start, s.
    pub t0: f64,
}

impl HeadOracle for TruthOracle {
    fn tracker_from_head(&self, t: f64) -> Option<Isometry3<f64>> {
        self.truth.at(t - self.t0)
    }
}

/// The oracle's tracker: the true head at the clock's time, with no latency, noise or gap, one
/// sample per tick.
pub struct OracleSource {
    oracle: TruthOracle,
    clock: Arc<dyn Clock>,
    last: f64,
}

impl std::fmt::Debug for OracleSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OracleSource")
            .field("oracle", &self.oracle)
            .field("last", &self.last)
            .finish_non_exhaustive()
    }
}

impl OracleSource {
    /// A source of `oracle`'s head on `clock`.
    pub fn new(oracle: TruthOracle, clock: Arc<dyn Clock>) -> Self {
        Self {
            oracle,
            clock,
            last: f64::NEG_INFINITY,
        }
    }
}

impl PoseSource for OracleSource {
    fn latest(&mut self) -> Option<PoseSample> {
        let now = self.clock.now_s();
        if now <= self.last {
            return None;
        }
        self.last = now;
        Some(PoseSample {
            tracker_from_marker: self.oracle.tracker_from_head(now)?,
            acquired_s: now,
            valid: true,
            error_m: 0.0,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::SteppedClock;
    use mocomp_geom::nalgebra::Vector3;
    use mocomp_kin::Model;

    fn truth() -> HeadTruth {
        let q: Vec<[f64; 6]> = (0..=100)
            .map(|k| {
                let t = k as f64 * 0.002;
                [0.1 * t, -1.5 + t, 1.2, -1.0, -1.5, 0.3 * t]
            })
            .collect();
        HeadTruth::new(
            Arm::new(Model::Ur3e),
            Isometry3::new(Vector3::new(0.5, 0.0, 1.0), Vector3::new(0.0, 2.0, 0.0)),
            Isometry3::translation(0.0, 0.0, 0.1),
            0.002,
            q,
        )
    }

    #[test]
    fn the_truth_is_the_ticks_joints_and_linear_between_them() {
        let h = truth();
        assert!((h.span_s() - 0.2).abs() < 1e-12);
        let q = h.joints_at(0.051).unwrap();
        assert!((q[1] - (-1.5 + 0.051)).abs() < 1e-12, "{q:?}");
        // At a tick, exactly the tick's joints through the forward kinematics.
        let at = h.at(0.05).unwrap();
        let by_hand = h.tracker_from_base * h.arm.fk_flange(&h.q[25]) * h.e2_from_head;
        assert!((at.translation.vector - by_hand.translation.vector).norm() < 1e-12);
        // Beyond the ends it holds.
        assert_eq!(h.joints_at(-1.0).unwrap(), h.q[0]);
        assert_eq!(h.joints_at(5.0).unwrap(), h.q[100]);
        let empty = HeadTruth::new(h.arm, h.tracker_from_base, h.e2_from_head, 0.002, vec![]);
        assert!(empty.at(0.0).is_none());
    }

    #[test]
    fn the_oracle_runs_on_the_loops_clock_and_its_source_gives_one_sample_per_tick() {
        let h = Arc::new(truth());
        let clock = Arc::new(SteppedClock::new(100.0));
        let oracle = TruthOracle {
            truth: Arc::clone(&h),
            t0: 100.0,
        };
        let close = |a: Isometry3<f64>, b: Isometry3<f64>| {
            (a.translation.vector - b.translation.vector).norm() < 1e-9
                && a.rotation.angle_to(&b.rotation) < 1e-9
        };
        let future = oracle.tracker_from_head(100.03).unwrap();
        assert!(close(future, h.at(0.03).unwrap()));
        let mut source = OracleSource::new(oracle, clock.clone());
        let s = source.latest().unwrap();
        assert_eq!((s.acquired_s, s.valid), (100.0, true));
        assert!(close(s.tracker_from_marker, h.at(0.0).unwrap()));
        assert!(source.latest().is_none(), "one sample per tick");
        clock.advance(0.002);
        let s = source.latest().unwrap();
        assert!(close(s.tracker_from_marker, h.at(0.002).unwrap()));
    }
}
