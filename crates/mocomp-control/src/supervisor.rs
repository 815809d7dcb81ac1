//! The supervisor: rules in, one reaction out.
//!
//! Each cycle the loop evaluates its rules (the tracker's, the robot's, the goal's, the command's
//! clearance checks); each rule that fires names a [`Reason`], and [`reaction`] maps it to what
//! the loop does. That mapping is the table below, the one place to read or change the policy:
//!
//! | rule ([`Reason`]) | reaction | why |
//! |---|---|---|
//! | `NoTracker` | hold | nothing to follow yet |
//! | `TrackerStale` (lost longer than `tracker_stale_s + coast_s`) | hold | where the head is is unknown; moving blind is worse than staying |
//! | `TrackerInputFailed` (the thread feeding the tracker failed, and no sample came since) | hold | as a lost tracker, with the cause named; the input reconnects by itself |
//! | `TrackerFrozen` | hold | a frozen stream looks like a still head but is not one |
//! | `MarkerInvalid` (longer than the coast time) | hold | as a lost tracker |
//! | `HeadTooFast` | retreat | a head faster than the robot may follow must not catch the coil: back off along the approach axis, keep following from there |
//! | `Robot` (a fault) | fault, latched | the controller stopped the arm itself (program stopped, protective or emergency stop, power off, connection lost): nothing moves until it is healthy and the operator resumes (re-arm, [`latches`]) |
//! | `RobotStale` | fault (latched past `robot_rearm_after_s`) | the robot's state is too old to command on; a short gap resumes by itself, by a path from where the arm is |
//! | `Singular` | hold | no safe joint motion near a singularity |
//! | `Unreachable` | hold | no IK solution on the current branch |
//! | `GoalInsideHead`, `GoalAxisOutward`, `GoalNotFinite`, `GoalNearScanEdge` | hold | the goal itself is wrong: fix the configuration (or, near a scan's edge, the scan) |
//! | `LinkCollision` | hold | an arm link near the head: the closing motion is refused, moving away stays allowed |
//! | `CoilCollision` | retreat | the head comes into the coil: the coil gives way along its axis, never the patient |
//! | `OffApproachAxis` | plan | near the head the coil comes in only along its axis: go round by the shell |
//! | `NoPath` | hold | no safe path to the goal |
//! | `NoTransit` | hold | no branch with a joint-space move to the goal's axis clear of the head and an approach from there: the goal is out of reach (move the patient or the robot), or the arm starts too close to the head (move it away by hand) |
//! | `Operator` | hold | the operator asked (the console's hold); every other rule outranks it |
//! | `ContactForce` (above `max_contact_force_n`) | retreat | the coil presses too hard: off the scalp now |
//! | `ContactForceSustained` (above `contact_warning_force_n` for `contact_warning_s`) | retreat | a lighter press held too long |
//! | `ForceSensorStale` | retreat | the force is unknown: a coil that may be pressing moves off rather than stand against a moving head |
//! | `ForceSaturated` | retreat | the sensor says only "at least its range" |
//! | `HandGuided` (the operator's free-drive) | hold | the hand moves the arm: the loop sends only free-drive's keep-alive; it resumes from the actual pose, by a path |
//! | `CalibrationInvalid` (the drift monitor: tracker or base moved) | hold | every goal computed through a wrong `base_from_tracker` is wrong by the offset: stop, recalibrate. It stays until the session clears it; the coil still gives way |
//!
//! ## Precedence
//!
//! When several rules fire in one cycle, one reason wins. A robot fault ([`robot_rules`],
//! latched by [`latches`]) comes first: it stops the arm and ends the cycle before any other
//! rule is read. [`decide`] then reads the others in this order, each overriding what came
//! before as said:
//!
//! 1. the tracker rules ([`tracker_rules`]);
//! 2. a wrong goal (`GoalInsideHead`, `GoalAxisOutward`, `GoalNotFinite`, `GoalNearScanEdge`),
//!    over the tracker's;
//! 3. `CalibrationInvalid`, over any hold so far but not over a retreat (a head too fast still
//!    makes the coil give way);
//! 4. `Operator`, only when nothing else fired;
//! 5. a force rule ([`crate::force`]), over all of them: a coil that may press on the scalp
//!    backs off whatever else holds, and its retreat ends only when clear for
//!    `contact_resume_s`.
//!
//! After the decision, the goal's own joints may still hold the loop (`Unreachable`,
//! `Singular`), and the checks on the command (`LinkCollision`, `CoilCollision`,
//! `OffApproachAxis`, `NoPath`, `NoTransit`) answer by their reaction on the command itself: they
//! judge a motion, so they come after the motion is chosen.
//!
//! A hold with the head in view still gives way: a held coil the head comes closer to than the
//! safety filter requires backs off along its axis (shown as a retreat for `CoilCollision`),
//! then holds again where it got to.
//!
//! Short tracker dropouts (up to `coast_s` beyond `tracker_stale_s`) are not a rule that fires:
//! the loop coasts on the prediction, with a standoff that grows with its uncertainty
//! (see [`crate::safety`]). The rule functions here are pure: no robot, no socket, no clock.

use crate::config::LoopParams;
use crate::goal::GoalError;
use mocomp_robot::{RobotFault, RobotState};

/// Why the loop does not simply track. Each is a named, tested rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reason {
    /// No tracker sample yet.
    NoTracker,
    /// The newest sample is older than `tracker_stale_s + coast_s` (its age, s).
    TrackerStale(f64),
    /// The thread feeding the tracker's samples failed (panicked, or ended when nobody asked)
    /// this many times, and no sample has come since: the tracker is lost for that named cause.
    TrackerInputFailed(u64),
    /// `frozen_samples` identical samples in a row.
    TrackerFrozen,
    /// The tracker has marked the marker invalid (lost, out of view) for longer than the coast
    /// time.
    MarkerInvalid,
    /// The head moves faster than the robot may follow (m/s, rad/s).
    HeadTooFast(f64, f64),
    /// The robot reports a fault.
    Robot(RobotFault),
    /// The robot's state was received longer ago than `robot_stale_s`.
    RobotStale,
    /// The goal is at or near a singularity (its margin).
    Singular(f64),
    /// No IK solution on the current branch within the joint limits.
    Unreachable,
    /// The goal puts the coil closer to the head than `coil_min_distance_m` (its distance, m).
    GoalInsideHead(f64),
    /// The command would bring a link (index) closer than the clearance (distance, m).
    LinkCollision(usize, f64),
    /// The command would bring the coil deeper than the contact tolerance (its distance, m).
    CoilCollision(f64),
    /// The coil near the head but off its approach axis (lateral offset, m).
    OffApproachAxis(f64),
    /// The goal's approach axis (+z of the coil) points out of the head.
    GoalAxisOutward,
    /// The goal is not a finite transform.
    GoalNotFinite,
    /// The goal's coil comes within `SCAN_CUT_KEEP_M` of where the scan the scalp came from
    /// ends inside the head (which face, and the coil's distance to it, m).
    GoalNearScanEdge(&'static str, f64),
    /// No safe path to the goal: unreachable, a branch change or a collision at this arc
    /// length along it (m), or no retreat to the shell (NaN).
    NoPath(f64),
    /// No joint-space transit to the goal's approach axis: why the furthest branch failed.
    NoTransit(TransitRefusal),
    /// The operator holds the loop (the console's or a front end's hold); the other rules
    /// outrank it.
    Operator,
    /// The contact force is above `max_contact_force_n` (N).
    ContactForce(f64),
    /// The contact force has been above `contact_warning_force_n` for longer than
    /// `contact_warning_s` (N now).
    ContactForceSustained(f64),
    /// The force reading has not changed for longer than `force_stale_s` (s).
    ForceSensorStale(f64),
    /// A force component at the end of the sensor's range (N).
    ForceSaturated(f64),
    /// Calibration no longer valid (tracker or base moved): a marker on the coil, seen by the
    /// tracker, is this far (m, rad) from where the robot and the calibration put it (the
    /// session's drift monitor, [`crate::Controller::set_calibration_invalid`]).
    CalibrationInvalid(f64, f64),
    /// The operator guides the arm by hand (free-drive): the loop commands nothing but
    /// free-drive's keep-alive, and comes back from where the hand left the coil, by a path.
    HandGuided,
}

/// Why no branch has a transit to the goal's approach axis, from the least to the most
/// promising: the furthest any branch got is the one reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum TransitRefusal {
    /// The pre-approach pose has no IK solution within the joint limits: the goal is out of the
    /// arm's reach where the head is (move the patient or the robot's base).
    Unreachable,
    /// Every solution there is near a singularity.
    Singular,
    /// Every straight joint-space move there passes the head (the coil or a link): move the arm
    /// away from the head first (free-drive or the pendant).
    Collision,
    /// From there no shell path reaches the goal on the same branch.
    NoApproach,
}

impl TransitRefusal {
    /// What the operator can do about it.
    pub fn advice(self) -> &'static str {
        match self {
            Self::Unreachable => {
                "the goal's approach pose is out of the arm's reach: move the patient or the robot"
            }
            Self::Singular => "every way to the goal's approach pose is near a singularity",
            Self::Collision => {
                "every joint move to the goal passes the head: move the arm away from the head \
                 (free-drive or the pendant), then resume"
            }
            Self::NoApproach => {
                "the goal cannot be approached along its axis from any branch: choose another goal"
            }
        }
    }
}

impl From<GoalError> for Reason {
    fn from(e: GoalError) -> Self {
        match e {
            GoalError::InsideHead { distance_m, .. } => Reason::GoalInsideHead(distance_m),
            GoalError::AxisOutward => Reason::GoalAxisOutward,
            GoalError::NotFinite => Reason::GoalNotFinite,
            GoalError::NearScanEdge { side, distance_m } => {
                Reason::GoalNearScanEdge(side, distance_m)
            }
        }
    }
}

/// What the loop does about a reason.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reaction {
    /// Follow the goal (nothing fired).
    Track,
    /// Go to the goal by a planned path around the head.
    Plan,
    /// Back off along the coil's approach axis to `retreat_distance_m` and keep following the
    /// head from there; come back in when the reason has been clear for `resume_after_s`.
    Retreat,
    /// Decelerate to standstill on the last safe command; resume when the reason has been clear
    /// for `resume_after_s`.
    Hold,
    /// Stop the robot; resume when it reports healthy.
    Fault,
}

/// The table: what the loop does for each rule.
pub fn reaction(reason: &Reason) -> Reaction {
    use Reaction::{Fault, Hold, Plan, Retreat};
    match reason {
        Reason::NoTracker => Hold,
        Reason::TrackerStale(_) => Hold,
        Reason::TrackerInputFailed(_) => Hold,
        Reason::TrackerFrozen => Hold,
        Reason::MarkerInvalid => Hold,
        Reason::HeadTooFast(..) => Retreat,
        Reason::Robot(_) => Fault,
        Reason::RobotStale => Fault,
        Reason::Singular(_) => Hold,
        Reason::Unreachable => Hold,
        Reason::GoalInsideHead(_) => Hold,
        Reason::GoalAxisOutward => Hold,
        Reason::GoalNotFinite => Hold,
        Reason::GoalNearScanEdge(..) => Hold,
        Reason::LinkCollision(..) => Hold,
        Reason::CoilCollision(_) => Retreat,
        Reason::OffApproachAxis(_) => Plan,
        Reason::NoPath(_) => Hold,
        Reason::NoTransit(_) => Hold,
        Reason::Operator => Hold,
        Reason::ContactForce(_) => Retreat,
        Reason::ContactForceSustained(_) => Retreat,
        Reason::ForceSensorStale(_) => Retreat,
        Reason::ForceSaturated(_) => Retreat,
        Reason::CalibrationInvalid(..) => Hold,
        Reason::HandGuided => Hold,
    }
}

/// The reasons the rules gave this cycle, the robot's aside (a fault ends the cycle first).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RuleInputs {
    /// The tracker rules' reason ([`tracker_rules`]).
    pub tracker: Option<Reason>,
    /// The goal check's ([`crate::goal::check_goal`]).
    pub goal: Option<Reason>,
    /// The drift monitor's offset while the calibration is not valid, m and rad.
    pub calibration: Option<(f64, f64)>,
    /// The operator holds.
    pub operator: bool,
    /// The force rules' ([`crate::force::force_rules`]).
    pub force: Option<Reason>,
}

/// The supervisor's decision: the winning reason and its reaction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The reason that won (`None`: nothing fired).
    pub reason: Option<Reason>,
    /// What the loop does about it.
    pub reaction: Reaction,
}

impl Decision {
    /// A reason that holds the loop whatever was decided before (the goal's joints).
    pub fn hold(reason: Reason) -> Self {
        Self {
            reason: Some(reason),
            reaction: Reaction::Hold,
        }
    }
}

/// One reason out of the rules that fired, by the precedence above.
pub fn decide(r: &RuleInputs) -> Decision {
    let mut reason = r.tracker;
    if r.goal.is_some() {
        reason = r.goal;
    }
    if let Some((m, a)) = r.calibration
        && reason.is_none_or(|r| reaction(&r) == Reaction::Hold)
    {
        reason = Some(Reason::CalibrationInvalid(m, a));
    }
    if r.operator && reason.is_none() {
        reason = Some(Reason::Operator);
    }
    if r.force.is_some() {
        reason = r.force;
    }
    Decision {
        reason,
        reaction: reason.map_or(Reaction::Track, |r| reaction(&r)),
    }
}

/// What the tracker rules see.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackerInputs {
    /// Whether any sample has been taken.
    pub initialised: bool,
    /// Whether the newest sample marks the marker valid.
    pub valid: bool,
    /// Age of the newest valid sample (by its acquisition time), s.
    pub age_s: f64,
    /// Identical samples in a row.
    pub identical: u32,
    /// The estimated head speed, m/s and rad/s.
    pub speed: (f64, f64),
    /// Failures of the thread feeding the samples since the newest sample (0: none).
    pub input_failures: u64,
}

/// The tracker rules' verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackerVerdict {
    /// A fresh sample: follow it.
    Fresh,
    /// A dropout short enough to coast on the prediction (the newest sample's age, s).
    Coasting(f64),
    /// A rule fired.
    Refused(Reason),
}

/// The tracker rules, in order: none yet, lost past the coast time, frozen, too fast; a short
/// dropout (late or invalid samples) is coasted.
pub fn tracker_rules(t: &TrackerInputs, p: &LoopParams) -> TrackerVerdict {
    let lost_after = p.tracker_stale_s + p.coast_s;
    if t.input_failures > 0 && (!t.initialised || t.age_s > lost_after) {
        return TrackerVerdict::Refused(Reason::TrackerInputFailed(t.input_failures));
    }
    if !t.initialised {
        return TrackerVerdict::Refused(Reason::NoTracker);
    }
    if t.age_s > lost_after {
        return TrackerVerdict::Refused(if t.valid {
            Reason::TrackerStale(t.age_s)
        } else {
            Reason::MarkerInvalid
        });
    }
    if t.identical >= p.frozen_samples {
        return TrackerVerdict::Refused(Reason::TrackerFrozen);
    }
    if t.speed.0 > p.max_head_speed_m_s || t.speed.1 > p.max_head_speed_rad_s {
        return TrackerVerdict::Refused(Reason::HeadTooFast(t.speed.0, t.speed.1));
    }
    if !t.valid || t.age_s > p.tracker_stale_s {
        return TrackerVerdict::Coasting(t.age_s);
    }
    TrackerVerdict::Fresh
}

/// Whether a robot rule that fired latches: the loop stays faulted after it clears, until the
/// operator re-arms it ([`crate::Controller::rearm`]). A fault the controller reports means it
/// stopped the arm on its own: what the arm and the patient did meanwhile is unknown, and the
/// operator looks before anything moves again. So does a state stream silent for
/// `robot_rearm_after_s` (`stale_for_s`: how long it has been), long past the program's
/// watchdog. A shorter gap is the loop's own stop, with the program still running: it resumes
/// by itself, by a path from where the arm is, never by a jump.
pub fn latches(reason: &Reason, stale_for_s: f64, p: &LoopParams) -> bool {
    match reason {
        Reason::Robot(_) => true,
        Reason::RobotStale => stale_for_s >= p.robot_rearm_after_s,
        _ => false,
    }
}

/// The robot rules: no state or one older than `robot_stale_s` (by the loop's clock), or a
/// fault the robot reports.
pub fn robot_rules(state: Option<&RobotState>, now_s: f64, p: &LoopParams) -> Option<Reason> {
    match state {
        None => Some(Reason::RobotStale),
        Some(s) if now_s - s.received_s > p.robot_stale_s => Some(Reason::RobotStale),
        Some(s) => s.fault().map(Reason::Robot),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_robot::SafetyMode;

    fn fresh() -> TrackerInputs {
        TrackerInputs {
            initialised: true,
            valid: true,
            age_s: 0.03,
            identical: 0,
            speed: (0.05, 0.3),
            input_failures: 0,
        }
    }

    fn verdict(f: impl FnOnce(&mut TrackerInputs)) -> TrackerVerdict {
        let mut t = fresh();
        f(&mut t);
        tracker_rules(&t, &LoopParams::default())
    }

    #[test]
    fn a_fresh_sample_of_a_moving_head_is_followed() {
        assert_eq!(verdict(|_| {}), TrackerVerdict::Fresh);
    }

    #[test]
    fn a_failed_input_is_named_once_the_tracker_is_lost_and_not_before() {
        let p = LoopParams::default();
        let lost = p.tracker_stale_s + p.coast_s + 0.001;
        // The reader failed but the next sample came within the coast time: followed.
        assert_eq!(verdict(|t| t.input_failures = 1), TrackerVerdict::Fresh);
        // Lost after it failed: the hold names the failure, not a stale tracker.
        let v = verdict(|t| {
            t.input_failures = 2;
            t.age_s = lost;
        });
        assert_eq!(v, TrackerVerdict::Refused(Reason::TrackerInputFailed(2)));
        let v = verdict(|t| {
            t.input_failures = 1;
            t.initialised = false;
        });
        assert_eq!(v, TrackerVerdict::Refused(Reason::TrackerInputFailed(1)));
        assert_eq!(reaction(&Reason::TrackerInputFailed(1)), Reaction::Hold);
    }

    #[test]
    fn no_sample_yet_holds() {
        let v = verdict(|t| t.initialised = false);
        assert_eq!(v, TrackerVerdict::Refused(Reason::NoTracker));
        assert_eq!(reaction(&Reason::NoTracker), Reaction::Hold);
    }

    #[test]
    fn a_short_dropout_is_coasted_and_a_long_one_holds() {
        let p = LoopParams::default();
        // Just late: coasted.
        let late = p.tracker_stale_s + 0.01;
        assert_eq!(verdict(|t| t.age_s = late), TrackerVerdict::Coasting(late));
        // An invalid marker within the coast time: coasted too.
        assert_eq!(
            verdict(|t| t.valid = false),
            TrackerVerdict::Coasting(fresh().age_s)
        );
        // Past the coast time: lost, held.
        let lost = p.tracker_stale_s + p.coast_s + 0.001;
        assert_eq!(
            verdict(|t| t.age_s = lost),
            TrackerVerdict::Refused(Reason::TrackerStale(lost))
        );
        assert_eq!(
            verdict(|t| {
                t.age_s = lost;
                t.valid = false;
            }),
            TrackerVerdict::Refused(Reason::MarkerInvalid)
        );
        assert_eq!(reaction(&Reason::TrackerStale(lost)), Reaction::Hold);
        assert_eq!(reaction(&Reason::MarkerInvalid), Reaction::Hold);
    }

    #[test]
    fn a_frozen_stream_holds() {
        let p = LoopParams::default();
        let v = verdict(|t| t.identical = p.frozen_samples);
        assert_eq!(v, TrackerVerdict::Refused(Reason::TrackerFrozen));
        assert_eq!(
            verdict(|t| t.identical = p.frozen_samples - 1),
            TrackerVerdict::Fresh
        );
        assert_eq!(reaction(&Reason::TrackerFrozen), Reaction::Hold);
    }

    #[test]
    fn a_head_too_fast_retreats_by_translation_or_rotation() {
        let p = LoopParams::default();
        let fast = (p.max_head_speed_m_s + 0.01, 0.1);
        assert!(matches!(
            verdict(|t| t.speed = fast),
            TrackerVerdict::Refused(Reason::HeadTooFast(..))
        ));
        let spinning = (0.01, p.max_head_speed_rad_s + 0.1);
        assert!(matches!(
            verdict(|t| t.speed = spinning),
            TrackerVerdict::Refused(Reason::HeadTooFast(..))
        ));
        assert_eq!(reaction(&Reason::HeadTooFast(1.0, 1.0)), Reaction::Retreat);
    }

    /// A healthy robot's state received at t = 1 s (the in-memory robot's).
    fn healthy() -> RobotState {
        let mut r = mocomp_testkit::mem::MemRobot::at(
            [0.0; 6],
            mocomp_geom::nalgebra::Isometry3::identity(),
            0.002,
        );
        r.tick(1.0);
        r.state
    }

    #[test]
    fn a_stale_or_faulted_robot_is_a_fault_and_a_late_one_is_not() {
        let p = LoopParams::default();
        let s = healthy();
        assert_eq!(robot_rules(Some(&s), 1.0 + p.robot_stale_s * 0.9, &p), None);
        assert_eq!(
            robot_rules(Some(&s), 1.0 + p.robot_stale_s * 1.1, &p),
            Some(Reason::RobotStale)
        );
        assert_eq!(robot_rules(None, 1.0, &p), Some(Reason::RobotStale));
        let mut stopped = healthy();
        stopped.safety_mode = SafetyMode::ProtectiveStop;
        let r = robot_rules(Some(&stopped), 1.0, &p).unwrap();
        assert!(matches!(r, Reason::Robot(_)));
        assert_eq!(reaction(&r), Reaction::Fault);
        assert_eq!(reaction(&Reason::RobotStale), Reaction::Fault);
    }

    #[test]
    fn a_fault_the_controller_reports_latches_and_only_a_long_stale_state_does() {
        let p = LoopParams::default();
        for f in [
            RobotFault::Disconnected,
            RobotFault::EmergencyStop,
            RobotFault::ProtectiveStop,
            RobotFault::ProgramStopped,
            RobotFault::NotRunning(mocomp_robot::RobotMode::PowerOff),
        ] {
            assert!(latches(&Reason::Robot(f), 0.0, &p), "{f:?}");
        }
        assert!(!latches(&Reason::RobotStale, p.robot_stale_s, &p));
        assert!(!latches(
            &Reason::RobotStale,
            p.robot_rearm_after_s * 0.99,
            &p
        ));
        assert!(latches(&Reason::RobotStale, p.robot_rearm_after_s, &p));
        // No other rule latches: the tracker's, the operator's and the force rules clear by
        // themselves (the operator's hold by the operator).
        for r in [
            Reason::TrackerStale(10.0),
            Reason::Operator,
            Reason::ContactForce(30.0),
            Reason::NoPath(0.1),
        ] {
            assert!(!latches(&r, 10.0, &p), "{r:?}");
        }
    }

    #[test]
    fn the_coil_gives_way_and_links_are_refused() {
        assert_eq!(reaction(&Reason::CoilCollision(-0.001)), Reaction::Retreat);
        assert_eq!(reaction(&Reason::LinkCollision(3, 0.005)), Reaction::Hold);
        assert_eq!(reaction(&Reason::OffApproachAxis(0.02)), Reaction::Plan);
    }

    #[test]
    fn the_decision_follows_the_precedence() {
        let d = |r: RuleInputs| decide(&r).reason;
        let stale = Some(Reason::TrackerStale(1.0));
        let fast = Some(Reason::HeadTooFast(1.0, 0.0));
        let goal = Some(Reason::GoalAxisOutward);
        let force = Some(Reason::ContactForce(40.0));
        let calibration = Some((0.01, 0.0));
        assert_eq!(decide(&RuleInputs::default()).reaction, Reaction::Track);
        // The operator only when nothing else fired.
        let op = RuleInputs {
            operator: true,
            ..Default::default()
        };
        assert_eq!(d(op), Some(Reason::Operator));
        assert_eq!(
            d(RuleInputs {
                tracker: stale,
                ..op
            }),
            stale
        );
        // A wrong goal over the tracker.
        assert_eq!(
            d(RuleInputs {
                tracker: stale,
                goal,
                ..op
            }),
            goal
        );
        // The calibration over a hold, not over a retreat.
        let cal = RuleInputs {
            calibration,
            ..Default::default()
        };
        assert_eq!(
            d(RuleInputs {
                tracker: stale,
                ..cal
            }),
            Some(Reason::CalibrationInvalid(0.01, 0.0))
        );
        assert_eq!(
            d(RuleInputs {
                tracker: fast,
                ..cal
            }),
            fast
        );
        assert_eq!(
            d(RuleInputs { goal, ..cal }),
            Some(Reason::CalibrationInvalid(0.01, 0.0))
        );
        // A force rule over everything.
        let all = RuleInputs {
            tracker: fast,
            goal,
            calibration,
            operator: true,
            force,
        };
        assert_eq!(d(all), force);
        assert_eq!(decide(&all).reaction, Reaction::Retreat);
    }

    #[test]
    fn a_wrong_goal_holds_whatever_its_fault() {
        for e in [
            GoalError::InsideHead {
                distance_m: -0.01,
                min_m: 0.0,
            },
            GoalError::AxisOutward,
            GoalError::NotFinite,
        ] {
            assert_eq!(reaction(&Reason::from(e)), Reaction::Hold, "{e:?}");
        }
        for r in [
            Reason::Singular(0.01),
            Reason::Unreachable,
            Reason::NoPath(0.1),
        ] {
            assert_eq!(reaction(&r), Reaction::Hold);
        }
    }
}
