//! Image-guided navigation's math, in metres and radians, with no I/O:
//! - [`capture`]: the operator's touches and sweep told apart in the pointer's stream;
//! - [`pivot`]: a tracked pointer's tip in its marker's frame, from pivoting it about a fixed
//!   point (robust least squares, refused without enough orientation spread);
//! - [`landmarks`]: the patient's head marker registered to the image on named anatomical
//!   landmarks (nasion, preauricular points, …) touched with that pointer: the least-squares
//!   rigid fit, its fiducial registration error per landmark;
//! - [`icp`]: that registration refined on points swept with the pointer over the scalp (rigid,
//!   robust point-to-plane ICP against the head model from the image);
//! - [`registration`]: the two together, and the error they leave at a target;
//! - [`tre`]: the target registration error that fit predicts at any target (Fitzpatrick, West
//!   and Maurer 1998), from the landmarks' configuration and the localisation error the FRE
//!   implies;
//! - [`eeg`]: the 10-20 and 10-10 positions on the patient's own scalp, from the nasion, the
//!   inion and the preauricular points;
//! - [`placement`]: a target in the image turned into the coil's pose over it.

pub mod capture;
pub mod eeg;
pub mod error;
pub mod icp;
pub mod landmarks;
pub mod pivot;
pub mod placement;
pub mod registration;
mod section;
pub mod tre;

pub use capture::{Capture, CaptureOptions, Captured, Step};
pub use eeg::{CranialLandmarks, EegPosition, System, eeg_positions};
pub use error::NavError;
pub use icp::{Anchors, IcpOptions, SurfaceRegistration, refine_on_surface};
pub use landmarks::{Landmark, LandmarkRegistration, register_landmarks};
pub use pivot::{PivotCalibration, calibrate_pivot};
pub use placement::{CoilPlacement, Handle, place_coil};
pub use registration::{Registration, register};
pub use tre::{fle_from_fre, predicted_tre};
