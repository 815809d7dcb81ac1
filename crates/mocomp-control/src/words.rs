//! The loop's reasons and events in an operator's words, with units (mm, degrees, N, ms):
//! what the console, the status lines and the run's summary show. The machine record (the CSV
//! log's `event` column, the JSON summary's `event_log`, ROS 2 diagnostics) keeps the stable
//! code (`Hold(NoPath(0.156))`) a script can match.

use crate::compensator::Event;
use crate::supervisor::{Reason, TransitRefusal};
use std::fmt;

/// The arm's links as [`crate::compensator`]'s collision check numbers them (the segment from
/// frame `i` to frame `i + 1` of a UR arm).
fn link_name(i: usize) -> &'static str {
    match i {
        1 => "the shoulder",
        2 => "the upper arm",
        3 => "the forearm",
        4 => "wrist 1",
        5 => "wrist 2",
        _ => "a link",
    }
}

/// Metres as millimetres, the unit an operator reads.
fn mm(m: f64) -> f64 {
    m * 1e3
}

impl fmt::Display for TransitRefusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Unreachable => "the approach pose is out of the arm's reach",
            Self::Singular => "every arm configuration at the approach pose is near a singularity",
            Self::Collision => "every joint move there passes the head",
            Self::NoApproach => "no arm configuration there can approach along the coil's axis",
        })
    }
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::NoTracker => f.write_str("no tracker sample yet"),
            Self::TrackerStale(age) => write!(f, "tracker silent for {:.0} ms", age * 1e3),
            Self::TrackerInputFailed(n) => write!(
                f,
                "the tracker's input failed ({n} times) and no sample has come since"
            ),
            Self::TrackerFrozen => f.write_str("the tracker repeats one sample (frozen)"),
            Self::MarkerInvalid => f.write_str("the head marker is out of the tracker's view"),
            Self::HeadTooFast(v, w) => write!(
                f,
                "the head moves too fast to follow ({:.0} mm/s, {:.0}°/s)",
                mm(v),
                w.to_degrees()
            ),
            Self::Robot(fault) => write!(f, "robot: {fault}"),
            Self::RobotStale => f.write_str("the robot's state is late"),
            Self::Singular(margin) => write!(
                f,
                "the arm would be near a singularity (margin {margin:.3} of 1)"
            ),
            Self::Unreachable => f.write_str(
                "the goal is out of the arm's reach in its present configuration \
                 (no joint solution within the limits)",
            ),
            Self::GoalInsideHead(d) if d < 0.0 => write!(
                f,
                "the goal puts the coil {:.1} mm inside the scalp",
                -mm(d)
            ),
            Self::GoalInsideHead(d) => write!(
                f,
                "the goal puts the coil {:.1} mm from the scalp, closer than allowed",
                mm(d)
            ),
            Self::LinkCollision(i, d) => write!(
                f,
                "{} would come within {:.0} mm of the head",
                link_name(i),
                mm(d).max(0.0)
            ),
            Self::CoilCollision(d) if d < 0.0 => {
                write!(f, "the coil would press {:.1} mm into the scalp", -mm(d))
            }
            Self::CoilCollision(d) => {
                write!(f, "the coil would come within {:.1} mm of the scalp", mm(d))
            }
            Self::OffApproachAxis(off) => write!(
                f,
                "the coil is near the head {:.0} mm off its approach axis",
                mm(off)
            ),
            Self::GoalAxisOutward => f.write_str("the goal's coil axis points out of the head"),
            Self::GoalNotFinite => f.write_str("the goal is not a finite pose"),
            Self::GoalNearScanEdge(side, d) => write!(
                f,
                "the goal is {:.0} mm from the {side} edge of the scan the scalp came from",
                mm(d)
            ),
            Self::NoPath(s) if s.is_nan() => {
                f.write_str("no path yet: the coil cannot back off to the safety shell")
            }
            Self::NoPath(s) => write!(
                f,
                "no path yet: the way around the head is blocked {:.0} mm along it",
                mm(s)
            ),
            Self::NoTransit(r) => write!(f, "no joint move to the goal's approach pose: {r}"),
            Self::Operator => f.write_str("held by the operator"),
            Self::ContactForce(n) => write!(f, "contact force {n:.1} N, above its limit"),
            Self::ContactForceSustained(n) => {
                write!(
                    f,
                    "contact force {n:.1} N, above its warning level for too long"
                )
            }
            Self::ForceSensorStale(s) => {
                write!(f, "the force reading has not changed for {s:.1} s")
            }
            Self::ForceSaturated(n) => {
                write!(f, "the force sensor is at the end of its range ({n:.0} N)")
            }
            Self::CalibrationInvalid(m, a) => write!(
                f,
                "calibration no longer valid: the coil's marker is {:.1} mm, {:.1}° from where \
                 the robot puts it",
                mm(m),
                a.to_degrees()
            ),
            Self::HandGuided => f.write_str("the operator guides the arm by hand"),
        }
    }
}

impl Reason {
    /// Whether the rule is about where the goal is for this arm (its reach, its singularities,
    /// the way to it) rather than about a moment (a stale sample, a force, the operator): a run
    /// held by one of these does not get better by waiting.
    pub fn is_placement(&self) -> bool {
        matches!(
            self,
            Self::Unreachable
                | Self::Singular(_)
                | Self::NoPath(_)
                | Self::NoTransit(_)
                | Self::LinkCollision(..)
                | Self::GoalInsideHead(_)
                | Self::GoalAxisOutward
                | Self::GoalNotFinite
                | Self::GoalNearScanEdge(..)
        )
    }

    /// What the operator can do about it, where the words say more than the reason.
    pub fn advice(&self) -> Option<&'static str> {
        Some(match self {
            Self::Unreachable
            | Self::Singular(_)
            | Self::NoPath(_)
            | Self::LinkCollision(..)
            | Self::NoTransit(TransitRefusal::Unreachable | TransitRefusal::Singular) => {
                "the target is not comfortably within the arm's reach where the head is: move \
                 the patient or the robot's base (`mocomp placement search --config FILE` finds \
                 a place that reaches every target; in the simulated world the head's place is \
                 `tracker.simulated.base_from_head`)"
            }
            Self::NoTransit(r) => r.advice(),
            Self::GoalInsideHead(_) | Self::GoalAxisOutward | Self::GoalNotFinite => {
                "the goal itself is wrong for this head: check `[goal]` or the target"
            }
            Self::GoalNearScanEdge(..) => {
                "the target is where the scan ends: choose a target inside the scanned scalp"
            }
            Self::NoTracker | Self::TrackerStale(_) | Self::TrackerInputFailed(_) => {
                "check the tracker's connection (`mocomp listen`)"
            }
            Self::MarkerInvalid => "bring the head marker into the tracker's view",
            Self::Robot(_) | Self::RobotStale => {
                "check the robot's pendant (mode, safety, program) and its connection"
            }
            _ => return None,
        })
    }
}

impl fmt::Display for Event {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Hold(r) => write!(f, "hold: {r}"),
            Self::Retreat(r) => write!(f, "backing off: {r}"),
            Self::Resume => f.write_str("resumed"),
            Self::Outlier(v, w) => write!(
                f,
                "tracker sample dropped as an outlier (it implies {:.0} mm/s, {:.0}°/s)",
                mm(v),
                w.to_degrees()
            ),
            Self::Reached => f.write_str("reached the goal: tracking"),
            Self::Coasting(age) => write!(
                f,
                "tracker dropout: coasting on the prediction (newest sample {:.0} ms old)",
                age * 1e3
            ),
            Self::Transit(q) => write!(
                f,
                "joint move to the goal's approach axis (largest joint turn {:.0}°)",
                q.to_degrees()
            ),
            Self::Rearmed => f.write_str("fault re-armed by the operator: coming back by a path"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_robot::RobotFault;

    fn every_reason() -> Vec<Reason> {
        vec![
            Reason::NoTracker,
            Reason::TrackerStale(0.25),
            Reason::TrackerInputFailed(2),
            Reason::TrackerFrozen,
            Reason::MarkerInvalid,
            Reason::HeadTooFast(0.31, 1.2),
            Reason::Robot(RobotFault::ProtectiveStop),
            Reason::RobotStale,
            Reason::Singular(0.0059),
            Reason::Unreachable,
            Reason::GoalInsideHead(-0.002),
            Reason::GoalInsideHead(0.001),
            Reason::LinkCollision(3, 0.004),
            Reason::CoilCollision(-0.0015),
            Reason::CoilCollision(0.0005),
            Reason::OffApproachAxis(0.012),
            Reason::GoalAxisOutward,
            Reason::GoalNotFinite,
            Reason::GoalNearScanEdge("inferior", 0.02),
            Reason::NoPath(0.156_471_622_164_854_2),
            Reason::NoPath(f64::NAN),
            Reason::NoTransit(TransitRefusal::Collision),
            Reason::Operator,
            Reason::ContactForce(12.5),
            Reason::ContactForceSustained(6.0),
            Reason::ForceSensorStale(2.0),
            Reason::ForceSaturated(50.0),
            Reason::CalibrationInvalid(0.0031, 0.02),
            Reason::HandGuided,
        ]
    }

    #[test]
    fn every_reason_reads_as_words_not_as_code() {
        for r in every_reason() {
            let text = r.to_string();
            let code = format!("{r:?}");
            assert_ne!(text, code);
            // No enum syntax, no seventeen-digit floats, no NaN.
            assert!(!text.contains("::") && !text.contains("NaN"), "{text}");
            // No rule's name (`NoPath`): a capital only as a unit (N) or a robot's own word.
            let camel = |w: &str| {
                w.chars().next().is_some_and(char::is_uppercase)
                    && w.chars().skip(1).any(char::is_lowercase)
            };
            assert!(!text.split_whitespace().any(camel), "{text}");
            assert!(
                !text
                    .split(|c: char| !c.is_ascii_digit())
                    .any(|d| d.len() > 4),
                "{text}"
            );
        }
    }

    #[test]
    fn lengths_are_millimetres_and_angles_degrees() {
        assert_eq!(
            Reason::NoPath(0.156_471_622_164_854_2).to_string(),
            "no path yet: the way around the head is blocked 156 mm along it"
        );
        assert_eq!(
            Reason::HeadTooFast(0.31, std::f64::consts::FRAC_PI_2).to_string(),
            "the head moves too fast to follow (310 mm/s, 90°/s)"
        );
        assert_eq!(
            Reason::CoilCollision(-0.0015).to_string(),
            "the coil would press 1.5 mm into the scalp"
        );
        assert_eq!(
            Event::Hold(Reason::TrackerStale(0.25)).to_string(),
            "hold: tracker silent for 250 ms"
        );
        assert_eq!(
            Event::Transit(std::f64::consts::FRAC_PI_4).to_string(),
            "joint move to the goal's approach axis (largest joint turn 45°)"
        );
    }

    #[test]
    fn placement_reasons_say_to_move_the_patient_or_the_robot() {
        for r in every_reason() {
            let advice = r.advice().unwrap_or("");
            let moves = advice.contains("move the patient or the robot");
            let expect = matches!(
                r,
                Reason::Unreachable
                    | Reason::Singular(_)
                    | Reason::NoPath(_)
                    | Reason::LinkCollision(..)
            );
            assert_eq!(moves, expect, "{r:?}: {advice}");
            if expect {
                assert!(r.is_placement(), "{r:?}");
            }
        }
        assert!(!Reason::Operator.is_placement());
        assert!(!Reason::TrackerStale(1.0).is_placement());
        assert!(Reason::NoTransit(TransitRefusal::Unreachable).is_placement());
    }
}
