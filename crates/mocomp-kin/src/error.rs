//! The error type of `mocomp-kin`.

use crate::branch::Branch;

/// Why a pose has no inverse kinematics solution.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum Unreachable {
    /// The wrist point (flange pulled back by `d6` along the tool z axis) lies inside the cylinder of
    /// radius `d4` about the base axis, which the shoulder offset can never reach.
    InsideShoulderCylinder {
        /// Horizontal distance of the wrist point from the base axis, metres.
        distance_m: f64,
        /// The cylinder's radius `d4`, metres.
        radius_m: f64,
    },
    /// The wrist 1 joint would have to be farther from the shoulder than the arm reaches.
    TooFar {
        /// Required shoulder–wrist 1 distance (the closest over all branches), metres.
        distance_m: f64,
        /// `|a2| + |a3|`, metres.
        reach_m: f64,
    },
    /// The wrist 1 joint would have to be closer to the shoulder than the folded arm allows.
    TooClose {
        /// Required shoulder–wrist 1 distance (the closest over all branches), metres.
        distance_m: f64,
        /// `||a2| − |a3||`, metres.
        min_m: f64,
    },
}

impl std::fmt::Display for Unreachable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Unreachable::InsideShoulderCylinder {
                distance_m,
                radius_m,
            } => write!(
                f,
                "the wrist point is {distance_m:.4} m from the base axis, inside the \
                 {radius_m:.4} m cylinder the shoulder offset cannot reach"
            ),
            Unreachable::TooFar {
                distance_m,
                reach_m,
            } => write!(
                f,
                "the wrist would be {distance_m:.4} m from the shoulder, beyond the arm's \
                 reach of {reach_m:.4} m"
            ),
            Unreachable::TooClose { distance_m, min_m } => write!(
                f,
                "the wrist would be {distance_m:.4} m from the shoulder, closer than the folded \
                 arm's {min_m:.4} m"
            ),
        }
    }
}

/// What can go wrong in `mocomp-kin`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum KinError {
    /// A model name not in the table.
    #[error("unknown robot model {name:?} (known: {known})")]
    UnknownModel {
        /// The name given.
        name: String,
        /// The names in the table.
        known: String,
    },
    /// An input number is NaN or infinite.
    #[error("{what}: element {index} is not a finite number ({value})")]
    NonFinite {
        /// Which input.
        what: &'static str,
        /// Index of the offending element.
        index: usize,
        /// The value found.
        value: f64,
    },
    /// The pose cannot be reached by the arm at all.
    #[error("pose unreachable: {0}")]
    Unreachable(Unreachable),
    /// Solutions exist, but none lies within the joint limits (with the margin asked for).
    #[error("pose reachable, but all {solutions} solutions violate the joint limits")]
    OutsideJointLimits {
        /// How many solutions were found before the limit check.
        solutions: usize,
    },
    /// Solutions exist, but none on the branch that was required.
    #[error("no solution on the {branch} branch (the pose is reachable only on another branch)")]
    BranchUnavailable {
        /// The branch that was required.
        branch: Branch,
    },
    /// With a calibrated model, Newton refinement of every closed-form start failed to converge.
    #[error("calibrated IK did not converge (best residual {residual:.3e})")]
    NotConverged {
        /// Smallest residual reached (metres + radians).
        residual: f64,
    },
    /// Joint limits that are not an interval.
    #[error("joint {joint} limits [{lower}, {upper}] are not a valid interval")]
    InvalidLimits {
        /// Joint index, 1-based.
        joint: usize,
        /// Lower limit, radians.
        lower: f64,
        /// Upper limit, radians.
        upper: f64,
    },
    /// A DH calibration file that cannot be used.
    #[error("DH calibration: {message}")]
    Calibration {
        /// What is wrong, with the location when the parser knows it.
        message: String,
    },
}
