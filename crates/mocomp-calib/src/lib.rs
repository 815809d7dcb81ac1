//! Hand-eye and robot-world calibration for mocomp: find `X = flange_from_marker` and
//! `Y = base_from_tracker` from pairs of `base_from_flange_i` (robot FK) and `tracker_from_marker_i`
//! (tracker measurements), with `base_from_flange_i · X = Y · tracker_from_marker_i`.
//!
//! Solvers: [`Method::Li`] (the seed paper's 24-unknown linear system, orthonormalised, translations
//! re-solved), [`Method::Shah`] (Kronecker product, rotations by SVD), [`Method::Refined`] (the
//! default: weighted nonlinear least squares on SE(3) from the better closed form, robust to outlier
//! pairs). Degenerate pose sets are named before anything is solved. [`plan`] proposes the robot
//! poses of a calibration run; [`procedure`] is the one procedure that collects them (the live
//! command's and the experiment's), through a [`procedure::Station`] the caller implements;
//! [`synth`] makes seeded synthetic pairs.
//!
//! No I/O: pairs files are parsed from text the caller reads.
//!
//! **Limits.** No I/O (pairs files are text the caller reads and writes); a robot and a tracker
//! only through the caller's [`procedure::Station`] and the robot's state (`mocomp-robot`, no
//! protocol): poses in, transforms out.

pub mod checks;
pub mod error;
pub mod linear;
pub mod noise;
pub mod pairs;
pub mod plan;
pub mod procedure;
pub mod refine;
pub mod report;
pub mod solve;
pub mod summary;
pub mod synth;

pub use error::CalibError;
pub use noise::NoiseModel;
pub use pairs::{Pair, PairsFormat, parse_pairs_csv, write_pairs_csv};
pub use report::{CalibrationFile, PairResidual, Uncertainty};
pub use solve::{Calibration, Method, SolveOptions, solve};
