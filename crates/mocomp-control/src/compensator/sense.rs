//! Sense: the tracker's samples taken into the head estimate ([`HeadState`]), the tracker rules'
//! verdict on it, the force sensor's filtered reading, and the head where it will be when this
//! cycle's command acts, with the clearance the coil must keep from it then.

use super::{Compensator, CycleRecord, Event, Mode};
use crate::config::LoopParams;
use crate::force::{ForceMonitor, force_rules};
use crate::predict::{PosePredictor, PredictorConfig};
use crate::safety::required_clearance;
use crate::supervisor::{Reaction, Reason, TrackerInputs, TrackerVerdict, reaction, tracker_rules};
use mocomp_geom::PoseSample;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_robot::RobotState;

/// Where the arm's state puts the flange and the coil against the goal for a head estimate.
#[derive(Debug, Clone, Copy)]
pub(super) struct Measured {
    /// The flange's distance from its goal, m and rad ([`CycleRecord::deviation`]).
    pub deviation: (f64, f64),
    /// The coil's, m and rad ([`CycleRecord::coil_error`]).
    pub coil_error: (f64, f64),
    /// The coil on the head ([`CycleRecord::coil_now`]).
    pub head_from_coil: Isometry3<f64>,
}

/// The tracker's side: the samples taken and the head estimate they make.
#[derive(Debug, Clone)]
pub(super) struct HeadState {
    pub(super) predictor: PosePredictor,
    /// The newest sample taken.
    pub(super) last_raw: Option<PoseSample>,
    /// Whether the newest sample marked the marker valid.
    pub(super) last_valid: bool,
    /// Identical samples in a row.
    pub(super) identical: u32,
    /// Whether the previous cycle coasted through a dropout.
    pub(super) coasting: bool,
    /// The source's failure count when the newest sample was taken, and now.
    pub(super) failures_at_sample: u64,
    pub(super) failures: u64,
    /// The head (`base_from_head`) the previous command was checked against.
    pub(super) last_head: Option<Isometry3<f64>>,
    /// The head's true pose at any time, for a bound no predictor can beat (the experiment's
    /// oracle); `None` for every real loop.
    pub(super) oracle: Option<std::sync::Arc<dyn HeadOracle>>,
}

/// Where the head truly is at any time, past or future (`tracker_from_head`, the tracker's
/// samples' frame): what the experiment's oracle controller knows and no real one can.
pub trait HeadOracle: std::fmt::Debug + Send + Sync {
    /// The head at time `t` (s, the loop's clock), if known then.
    fn tracker_from_head(&self, t: f64) -> Option<Isometry3<f64>>;
}

/// The force sensor's side.
#[derive(Debug, Clone)]
pub(super) struct ForceState {
    /// The wrench's filter and timers.
    pub(super) monitor: ForceMonitor,
    /// The force sensor's range, N (`None`: an estimate without one).
    pub(super) range: Option<f64>,
    /// The newest filtered axial force, N.
    pub(super) axial_n: f64,
}

/// Where the head will be when this cycle's command acts.
#[derive(Debug, Clone, Copy)]
pub(super) struct HeadEstimate {
    /// The head then, in the robot's base (`None`: not known well enough to move by).
    pub(super) base_from_head: Option<Isometry3<f64>>,
    /// The clearance the coil must keep from it, m.
    pub(super) required: f64,
    /// The head one controller period before `base_from_head`, by the same prediction (the
    /// oracle: the truth): the target's own speed along this cycle's prediction.
    pub(super) base_from_head_before: Option<Isometry3<f64>>,
}

impl HeadState {
    /// No sample yet.
    pub(super) fn new(predictor: PredictorConfig) -> Self {
        Self {
            predictor: PosePredictor::new(predictor),
            last_raw: None,
            last_valid: true,
            identical: 0,
            coasting: false,
            failures_at_sample: 0,
            failures: 0,
            last_head: None,
            oracle: None,
        }
    }

    /// Takes the newest tracker sample, applying the tracker rules. Returns an outlier event.
    pub(super) fn take_sample(
        &mut self,
        s: PoseSample,
        p: &LoopParams,
        period: f64,
    ) -> Option<Event> {
        if self.predictor.is_initialised() && s.acquired_s <= self.predictor.time_s() {
            // Acquired before the newest sample taken (a sender's clock stepped back, not yet
            // re-based): it says nothing about the head now, and judged as a motion it would
            // look like a jump. The newest sample keeps ageing, so the tracker rules hold.
            return None;
        }
        self.last_valid = s.valid;
        if !s.valid {
            return None;
        }
        if let Some(prev) = self.last_raw {
            if prev.tracker_from_marker == s.tracker_from_marker {
                self.identical = self.identical.saturating_add(1);
            } else {
                self.identical = 0;
            }
        }
        if self.predictor.is_initialised()
            && s.acquired_s - self.predictor.time_s() > p.tracker_stale_s + p.coast_s
        {
            // Back after the tracker was lost: the old rates mean nothing for the head now.
            self.predictor.reset();
            self.last_raw = None;
            self.identical = 0;
        }
        if let Some(pred) = self.predictor.predict(s.acquired_s) {
            let dt = (s.acquired_s - self.predictor.time_s()).max(period);
            let lin = (pred.translation.vector - s.tracker_from_marker.translation.vector).norm();
            let ang = (pred.rotation.inverse() * s.tracker_from_marker.rotation).angle();
            let (vl, va) = (lin / dt, ang / dt);
            if vl > p.outlier_speed_m_s || va > p.outlier_speed_rad_s {
                return Some(Event::Outlier(vl, va));
            }
        }
        self.last_raw = Some(s);
        self.failures_at_sample = self.failures;
        self.predictor.update(s.acquired_s, &s.tracker_from_marker);
        None
    }

    /// The source's failure count now (see [`mocomp_geom::PoseSource::failures`]).
    pub(super) fn note_failures(&mut self, failures: u64) {
        self.failures = failures;
    }

    /// The tracker rules' verdict at `now` (see [`crate::supervisor::tracker_rules`]).
    pub(super) fn verdict(&mut self, now: f64, p: &LoopParams) -> TrackerVerdict {
        let age = now - self.predictor.time_s();
        if self.predictor.is_initialised() && age > 10.0 * (p.tracker_stale_s + p.coast_s) {
            // A long dropout: the velocity estimate means nothing any more.
            self.predictor.reset();
            self.last_raw = None;
        }
        let (v, w) = self.predictor.velocity();
        tracker_rules(
            &TrackerInputs {
                initialised: self.predictor.is_initialised(),
                valid: self.last_valid,
                age_s: age,
                identical: self.identical,
                speed: (v.norm(), w.norm()),
                input_failures: self.failures - self.failures_at_sample.min(self.failures),
            },
            p,
        )
    }

    /// The estimated head speed, m/s and rad/s.
    pub(super) fn speed(&self) -> (f64, f64) {
        let (v, w) = self.predictor.velocity();
        (v.norm(), w.norm())
    }

    /// The newest sample's age at `now`, s (NaN before the first: not the time since the
    /// predictor's t = 0).
    pub(super) fn age(&self, now: f64) -> f64 {
        if self.predictor.is_initialised() {
            now - self.predictor.time_s()
        } else {
            f64::NAN
        }
    }
}

impl Compensator {
    /// The tracker rules now: the reason they refuse the head, if any; a coasting event when a
    /// dropout begins.
    pub(super) fn tracker_phase(
        &mut self,
        now: f64,
        rec: &mut CycleRecord,
        event: &mut Option<Event>,
    ) -> Option<Reason> {
        let verdict = self.head.verdict(now, &self.cfg.params);
        rec.head_speed = self.head.speed();
        rec.sample_age_s = self.head.age(now);
        let coasting = matches!(verdict, TrackerVerdict::Coasting(_));
        if let TrackerVerdict::Coasting(age) = verdict
            && !self.head.coasting
        {
            *event = event.or(Some(Event::Coasting(age)));
        }
        self.head.coasting = coasting;
        rec.coasting = coasting;
        match verdict {
            TrackerVerdict::Refused(r) => Some(r),
            TrackerVerdict::Fresh | TrackerVerdict::Coasting(_) => None,
        }
    }

    /// The force rules, on the wrench of this state (none without `force_sensing`).
    pub(super) fn force_phase(
        &mut self,
        state: &RobotState,
        rec: &mut CycleRecord,
    ) -> Option<Reason> {
        let p = &self.cfg.params;
        if !p.force_sensing {
            return None;
        }
        let axis = (self.arm.fk_flange(&state.actual_q) * self.cfg.flange_from_coil).rotation
            * Vector3::z();
        let f = self
            .force
            .monitor
            .update(state.controller_s, &state.tcp_force, &axis, p);
        rec.contact_force_n = f.force_n;
        rec.contact_axial_n = f.axial_n;
        self.force.axial_n = f.axial_n;
        force_rules(&f, p, self.force.range)
    }

    /// The head where it will be when this cycle's command acts, and the clearance the coil
    /// must keep from it then. Known while tracking, coasting, and retreating from a head too
    /// fast to follow (`tracker`: the tracker rules' reason); a force rule that fired (`force`)
    /// backs off from the last head known. Also measures the arm's errors against the head now.
    pub(super) fn head_estimate(
        &self,
        now: f64,
        tracker: Option<Reason>,
        force: bool,
        q_actual: &[f64; 6],
        rec: &mut CycleRecord,
    ) -> HeadEstimate {
        let p = &self.cfg.params;
        let head_known =
            tracker.is_none() || tracker.is_some_and(|r| reaction(&r) == Reaction::Retreat);
        let mut base_from_head = None;
        let mut base_from_head_before = None;
        let mut required = p.coil_min_distance_m;
        if head_known {
            let predictor = &self.head.predictor;
            // The servo follows its setpoint with a lag of the lookahead less one controller
            // period (the cycle that takes a setpoint already moves towards it; measured on
            // the simulated controller: 22 ms for 30 ms on a CB3, 28 ms on an e-Series).
            let servo_lag = (self.cfg.servo.lookahead_s - self.period).max(0.0);
            let target_t = now + self.cmd.delay.estimate() + servo_lag;
            let (head, sigma) = if let Some(oracle) = &self.head.oracle {
                rec.horizon_s = target_t - predictor.time_s();
                (oracle.tracker_from_head(target_t), (0.0, 0.0))
            } else if p.predict {
                rec.horizon_s = target_t - predictor.time_s();
                (predictor.predict(target_t), predictor.sigma(target_t))
            } else {
                (
                    self.head.last_raw.map(|s| s.tracker_from_marker),
                    predictor.sigma(predictor.time_s()),
                )
            };
            if p.predict || self.head.oracle.is_some() {
                rec.head_at_target = head.map(|h| (target_t, h));
                let before = target_t - self.period;
                base_from_head_before = match &self.head.oracle {
                    Some(oracle) => oracle.tracker_from_head(before),
                    None => predictor.predict(before),
                }
                .map(|h| self.cfg.base_from_tracker * h);
            }
            if let Some(tracker_from_head) = head {
                base_from_head = Some(self.cfg.base_from_tracker * tracker_from_head);
                required = required_clearance(p, sigma.0, sigma.1, self.goal.coil_lever);
            }
        }
        if base_from_head.is_none() && force {
            // Backing off needs a head to back off from: the last one known, where the coil
            // was pressing.
            base_from_head = self.head.last_head;
        }
        if self.in_contact_mode() {
            // On the scalp by design: the force rules guard the contact, the filter only how
            // deep the coil may go.
            required = -p.contact_max_press_m;
        }
        rec.required_m = required;
        let head_now = match &self.head.oracle {
            Some(oracle) => oracle.tracker_from_head(now),
            None => self.head.predictor.predict(now),
        };
        if head_known && let Some(tracker_from_head) = head_now {
            rec.head_now = Some(tracker_from_head);
            let m = self.measured(q_actual, &tracker_from_head);
            (rec.deviation, rec.coil_error, rec.coil_now) =
                (m.deviation, m.coil_error, Some(m.head_from_coil));
        }
        HeadEstimate {
            base_from_head,
            required,
            base_from_head_before,
        }
    }

    /// The measured flange's and the measured coil's errors (m, rad) against the goal for the
    /// head at `tracker_from_head`, and the measured coil on that head, with the arm at `q`.
    pub(super) fn measured(&self, q: &[f64; 6], tracker_from_head: &Isometry3<f64>) -> Measured {
        let goal_now = self.goal_for(tracker_from_head);
        let flange = self.arm.fk_flange(q);
        let angle = flange.rotation.angle_to(&goal_now.rotation);
        let (coil, coil_goal) = (
            flange * self.cfg.flange_from_coil,
            goal_now * self.cfg.flange_from_coil,
        );
        Measured {
            deviation: (
                (flange.translation.vector - goal_now.translation.vector).norm(),
                angle,
            ),
            coil_error: (
                (coil.translation.vector - coil_goal.translation.vector).norm(),
                angle,
            ),
            head_from_coil: (self.cfg.base_from_tracker * tracker_from_head).inv_mul(&coil),
        }
    }

    /// Whether contact mode holds the coil on the scalp now (following the goal).
    pub(super) fn in_contact_mode(&self) -> bool {
        let p = &self.cfg.params;
        p.contact_mode && p.force_sensing && self.mode == Mode::Tracking
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn sample(t: f64, x: f64) -> PoseSample {
        PoseSample {
            tracker_from_marker: Isometry3::translation(x, 0.0, 1.0),
            acquired_s: t,
            valid: true,
            error_m: f64::NAN,
        }
    }

    fn head() -> HeadState {
        HeadState::new(PredictorConfig::default())
    }

    #[test]
    fn a_jump_faster_than_any_head_is_an_outlier_and_not_taken() {
        let p = LoopParams::default();
        let mut h = head();
        for k in 0..10 {
            assert_eq!(h.take_sample(sample(k as f64 / 60.0, 0.0), &p, 0.002), None);
        }
        let before = h.predictor.time_s();
        let e = h.take_sample(sample(10.0 / 60.0, 0.2), &p, 0.002);
        assert!(
            matches!(e, Some(Event::Outlier(v, _)) if v > p.outlier_speed_m_s),
            "{e:?}"
        );
        assert_eq!(h.predictor.time_s(), before, "the outlier was taken");
    }

    #[test]
    fn a_sample_older_than_the_newest_is_ignored_and_the_head_ages() {
        let p = LoopParams::default();
        let mut h = head();
        for k in 0..10 {
            h.take_sample(sample(k as f64 / 60.0, 0.0), &p, 0.002);
        }
        let newest = h.predictor.time_s();
        // A clock stepped back 1 s: an old time, and a position that would be a jump.
        assert_eq!(h.take_sample(sample(newest - 1.0, 0.3), &p, 0.002), None);
        assert_eq!(h.predictor.time_s(), newest);
        let late = newest + p.tracker_stale_s + p.coast_s + 0.01;
        assert!(matches!(
            h.verdict(late, &p),
            TrackerVerdict::Refused(Reason::TrackerStale(_))
        ));
    }

    #[test]
    fn identical_samples_freeze_and_a_short_gap_coasts() {
        let p = LoopParams::default();
        let mut h = head();
        let mut t = 0.0;
        for _ in 0..=p.frozen_samples {
            h.take_sample(sample(t, 0.0), &p, 0.002);
            t += 1.0 / 60.0;
        }
        assert_eq!(
            h.verdict(t, &p),
            TrackerVerdict::Refused(Reason::TrackerFrozen)
        );
        let mut h = head();
        h.take_sample(sample(0.0, 0.0), &p, 0.002);
        h.take_sample(sample(1.0 / 60.0, 0.0001), &p, 0.002);
        let gap = 1.0 / 60.0 + p.tracker_stale_s + 0.5 * p.coast_s;
        assert!(matches!(h.verdict(gap, &p), TrackerVerdict::Coasting(_)));
        assert!(h.age(gap) > p.tracker_stale_s);
        assert!(head().age(1.0).is_nan());
    }
}
