//! The error type of `mocomp-calib`.

/// Where a pair came from, for messages: its index in the set and, when read from a file, its line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PairRef {
    /// 0-based index in the pair set.
    pub index: usize,
    /// 1-based line in the pairs file, when known.
    pub line: Option<usize>,
}

impl std::fmt::Display for PairRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.line {
            Some(l) => write!(f, "pair {} (line {l})", self.index + 1),
            None => write!(f, "pair {}", self.index + 1),
        }
    }
}

/// What can go wrong in calibration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum CalibError {
    /// A pairs file cell, column or line that cannot be used.
    #[error("{file}: line {line}{}: {message}", column.map(|c| format!(", column {c}")).unwrap_or_default())]
    PairsFile {
        /// File name as given (or "<input>").
        file: String,
        /// 1-based line.
        line: usize,
        /// 1-based column, when the problem is one cell.
        column: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// Fewer pairs than the problem needs.
    #[error("{found} pairs: at least 3 are needed (with rotations about two different axes)")]
    TooFewPairs {
        /// Pairs given.
        found: usize,
    },
    /// A number is NaN or infinite.
    #[error("{pair}: {what} is not finite")]
    NonFinite {
        /// The pair.
        pair: PairRef,
        /// Which transform.
        what: &'static str,
    },
    /// Two pairs with the same robot pose: no new information, usually a logging error.
    #[error("{first} and {second} have the same robot pose (within 0.1 mm and 0.05°)")]
    DuplicatePoses {
        /// The first pair.
        first: PairRef,
        /// The duplicate.
        second: PairRef,
    },
    /// The robot barely rotated: rotations carry the information about X and Y.
    #[error(
        "the largest rotation between robot poses is {max_deg:.2}°: rotate the flange by 15°–40° \
         about several axes"
    )]
    RotationsTooSmall {
        /// Largest relative rotation angle, degrees.
        max_deg: f64,
    },
    /// All relative rotations are about (nearly) one axis: X and Y are not determined about it.
    #[error(
        "all robot rotations are about one axis (base frame direction [{:.3}, {:.3}, {:.3}]; \
         spread {spread:.3}): rotate about at least two different axes",
        axis[0], axis[1], axis[2]
    )]
    SingleAxis {
        /// The common axis in the base frame.
        axis: [f64; 3],
        /// Second over first singular value of the relative rotation vectors (0 = one axis).
        spread: f64,
    },
    /// The tracker's view of the motion between pairs disagrees with the robot's for most pairs:
    /// the marker moved on the flange, the tracker moved, or the rows of robot and tracker data do
    /// not belong together.
    #[error(
        "measurements are not rigid: {inconsistent} of {total} pair combinations disagree, e.g. \
         {example}"
    )]
    NonRigid {
        /// Pair combinations whose invariants disagree.
        inconsistent: usize,
        /// Pair combinations compared.
        total: usize,
        /// The worst disagreement, in words.
        example: String,
    },
    /// The linear system has no unique solution (degenerate pose set).
    #[error("the {method} system is rank deficient: the pose set does not determine X and Y")]
    Singular {
        /// Which solver.
        method: &'static str,
    },
    /// Too many pairs would be left out as outliers to keep a solvable set.
    #[error("{outliers} of {total} pairs are outliers; fewer than 3 consistent pairs remain")]
    TooManyOutliers {
        /// Outliers found.
        outliers: usize,
        /// Pairs given.
        total: usize,
    },
    /// Pose planning could not find enough valid poses.
    #[error(
        "planned {found} of {wanted} poses ({unreachable} candidates unreachable on the current \
         branch, {near_singular} near a singularity, {not_visible} not visible to the tracker)"
    )]
    PlanShort {
        /// Poses found.
        found: usize,
        /// Poses asked for.
        wanted: usize,
        /// Candidates rejected by IK.
        unreachable: usize,
        /// Candidates rejected for singularity.
        near_singular: usize,
        /// Candidates rejected for visibility.
        not_visible: usize,
    },
    /// Invalid options (noise model, planner settings).
    #[error("{0}")]
    InvalidOption(String),
    /// A calibration result file that cannot be used.
    #[error("calibration file: {0}")]
    ResultFile(String),
}
