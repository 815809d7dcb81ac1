//! The error type of `mocomp-geom`.

/// What can go wrong when building or combining poses.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GeomError {
    /// An input number is NaN or infinite.
    #[error("{what}: element {index} is not a finite number ({value})")]
    NonFinite {
        /// Which input (e.g. "UR pose vector", "homogeneous matrix").
        what: &'static str,
        /// Index of the offending element (row-major for matrices).
        index: usize,
        /// The value found.
        value: f64,
    },
    /// A homogeneous matrix whose last row is not `[0, 0, 0, 1]`.
    #[error("homogeneous matrix: last row is {row:?}, expected [0, 0, 0, 1]")]
    BadBottomRow {
        /// The row found.
        row: [f64; 4],
    },
    /// A rotation block that is not orthonormal within the tolerance.
    #[error(
        "rotation block is not orthonormal: max |RᵀR − I| = {deviation:.3e} exceeds {tolerance:.1e}"
    )]
    NotOrthonormal {
        /// Largest absolute entry of `RᵀR − I`.
        deviation: f64,
        /// The tolerance allowed.
        tolerance: f64,
    },
    /// A rotation block with a negative determinant (a reflection, not a rotation).
    #[error("rotation block is a reflection (determinant {det:.6})")]
    Reflection {
        /// The determinant found.
        det: f64,
    },
    /// A quaternion whose norm is too far from 1 to be a rotation.
    #[error("quaternion norm {norm:.6} differs from 1 by more than {tolerance}")]
    QuaternionNorm {
        /// The norm found.
        norm: f64,
        /// The tolerance allowed.
        tolerance: f64,
    },
    /// Averaging needs at least one pose.
    #[error("cannot average an empty set of poses")]
    Empty,
    /// The number of weights differs from the number of poses.
    #[error("{poses} poses but {weights} weights")]
    WeightCount {
        /// Number of poses.
        poses: usize,
        /// Number of weights.
        weights: usize,
    },
    /// A weight is negative or not finite.
    #[error("weight {index} is {value}: weights must be finite and non-negative")]
    BadWeight {
        /// Index of the weight.
        index: usize,
        /// The value found.
        value: f64,
    },
    /// All weights are zero.
    #[error("the weights sum to zero")]
    ZeroWeightSum,
    /// The rotations are spread so that their mean is not unique (e.g. two rotations 180° apart).
    #[error(
        "the mean rotation is not unique (eigenvalue gap {gap:.3e}); the rotations are spread too far"
    )]
    AmbiguousMean {
        /// Gap between the two largest eigenvalues of the quaternion scatter matrix.
        gap: f64,
    },
    /// A matrix too close to rank 1 to have a unique nearest rotation.
    #[error("matrix has singular values {singular_values:?}: no unique nearest rotation")]
    RankDeficient {
        /// The singular values, largest first.
        singular_values: [f64; 3],
    },
}
