//! Pose math for mocomp: rigid transforms, the UR pose vector, homogeneous matrices, quaternions,
//! pose error metrics (including the seed paper's Frobenius deviation `d`), SE(3) interpolation,
//! averaging and orthonormalisation; the timestamped sample types and the lock-free newest-value
//! cell shared by the I/O clients.
//!
//! # Conventions
//! - Units inside are metres and radians. Millimetres and degrees appear only in functions whose
//!   name says so (`*_mm`, `deg_*`), for the I/O edges that need them.
//! - A transform `a_from_b: Isometry3<f64>` maps points expressed in frame `b` into frame `a`, so
//!   chains read left to right:
//!   `base_from_flange = base_from_tracker * tracker_from_head * head_from_coil * coil_from_flange`.
//! - Nothing here does I/O or spawns a thread; [`MonotonicClock`] is the only clock reader, for
//!   the edges to create and hand to the loop.
//!
//! `nalgebra` is re-exported so that every mocomp crate uses the one version pinned here.
//!
//! **Limits.** No I/O, no threads, no clock reads: pure math and types, depended on by every crate
//! and depending on none of mocomp's.

pub mod error;
pub mod fit;
pub mod interp;
pub mod latest;
pub mod metrics;
pub mod pose;
pub mod sample;
pub mod seqlock;
pub mod text;
pub mod units;
pub mod watch;

pub use error::GeomError;
pub use interp::{average, interpolate, slerp};
pub use latest::LatestCell;
pub use metrics::{LengthUnit, PoseError, frobenius_deviation, rotation_error, translation_error};
pub use nalgebra;
pub use pose::orthonormalize;
pub use pose::{
    RIGID_TOLERANCE, iso_from_matrix, iso_from_matrix_mm, iso_from_rows, iso_from_ur_pose,
    iso_from_wxyz, matrix_from_iso, matrix_mm_from_iso, quat_from_rotvec, rotvec_from_quat,
    rows_from_iso, ur_pose_from_iso, ur_pose_near, wxyz_from_iso,
};
pub use sample::{Clock, MonotonicClock, PoseSample, PoseSource, SteppedClock};
pub use seqlock::SeqLock;
pub use watch::Watch;

/// A rigid transform `a_from_b` (rotation and translation in metres).
pub type Pose = nalgebra::Isometry3<f64>;
