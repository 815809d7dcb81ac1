//! Image-guided navigation's math, in metres and radians, with no I/O:
//! - [`pivot`]: a tracked pointer's tip in its marker's frame, from pivoting it about a fixed
//!   point (robust least squares, refused without enough orientation spread);
//! - [`capture`]: a landmark's touch told apart in the pointer's stream from a pause in the air;
//! - [`sweep`]: the scalp swept with the pointer, told apart from the pointer approaching,
//!   lifting off or paused;
//! - [`noise`]: what each input to a registration is worth, stated, never learned from the fit;
//! - [`solve`]: the landmarks and the swept points as one weighted least-squares problem, with
//!   the pose's covariance from its information;
//! - [`registration`]: the whole registration, each landmark's error and consistency, and the
//!   error bound at any target;
//! - [`bound`]: the radius holding a Gaussian error with a given probability, and the chi-square
//!   distribution of the consistency tests;
//! - [`regions`]: the scalp's named regions, and the one whose sweep would help most;
//! - [`verdict`]: whether a registration may be used, and what to redo if not;
//! - [`procedure`]: the operator's procedure, from the first touch to the verdict;
//! - [`landmarks`]: the landmarks' rigid fit (the procedure's start);
//! - [`eeg`]: the 10-20 and 10-10 positions on the patient's own scalp, from the nasion, the
//!   inion and the preauricular points;
//! - [`placement`]: a target in the image turned into the coil's pose over it;
//! - [`dose_search`]: the place and turn of the coil near it that give the target the largest
//!   field (targeting by dose).

pub mod bound;
pub mod capture;
pub mod dose_search;
pub mod eeg;
pub mod error;
pub mod landmarks;
pub mod noise;
pub mod pivot;
pub mod placement;
pub mod procedure;
pub mod regions;
pub mod registration;
pub mod scalp;
mod section;
pub mod solve;
pub mod sweep;
pub mod verdict;

pub use capture::{CaptureOptions, Captured, LandmarkCapture, Touch};
pub use dose_search::{CoilOver, DoseAlong, DoseMap, DosePlace, DoseSearch, FieldAt};
pub use eeg::{CranialLandmarks, EegPosition, System, eeg_positions};
pub use error::NavError;
pub use landmarks::{Landmark, LandmarkRegistration, register_landmarks};
pub use noise::NoiseModel;
pub use pivot::{PivotCalibration, calibrate_pivot};
pub use placement::{CoilPlacement, Handle, place_coil};
pub use procedure::{Notice, Outcome, Procedure, Prompt, Settings};
pub use registration::{CONFIDENCE, Registration, register};
pub use scalp::Scalp;
pub use sweep::SweepOptions;
pub use verdict::{Limits, Refusal, Target};
