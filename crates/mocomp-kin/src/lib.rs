//! Universal Robots kinematics for mocomp: the model table (DH parameters, joint limits, maximum
//! joint speeds), forward kinematics of the flange, the tool and every link frame, closed-form
//! inverse kinematics with all (up to) eight solutions labelled by branch, the choice of one
//! solution near the current joints, the geometric Jacobian and singularity measures, and loading
//! a robot's own calibrated DH values.
//!
//! Units are metres and radians. No I/O: calibration files are parsed from strings that the caller
//! reads.
//!
//! ```
//! use mocomp_kin::{Arm, Model, Selection};
//! let arm = Arm::new(Model::Ur5e);
//! let current = [0.1, -1.2, 1.3, -0.4, 0.7, 0.2];
//! let goal = arm.fk(&[0.15, -1.25, 1.35, -0.4, 0.7, 0.25]);
//! let all = arm.ik(&goal, current[5]).unwrap();
//! assert_eq!(all.len(), 8);
//! let chosen = arm.choose(&all, &current, &Selection::tracking(0.05)).unwrap();
//! assert!((chosen.joints[0] - 0.15).abs() < 1e-9);
//! ```
//!
//! **Limits.** No I/O and no robot connection: kinematics from the model table (or a calibration
//! file's values passed in), never from a controller.

pub mod arm;
pub mod branch;
pub mod dh;
pub mod error;
pub mod ik;
pub mod model;
pub mod report;
pub mod select;

pub use arm::{Arm, JointLimits, Singularity, fk_nominal};
pub use branch::{Branch, Elbow, Shoulder, Wrist};
pub use dh::{DhCalibration, DhParams};
pub use error::{KinError, Unreachable};
pub use ik::{BranchCoordinates, IkSolution, SingularCases, Solutions};
pub use model::{MODELS, Model, ModelSpec, Series, UrGeometry};
pub use select::{BranchPolicy, Choice, Metric, Selection};
