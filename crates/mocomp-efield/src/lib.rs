//! The dose a TMS pulse gives: the electric field a coil induces at a point in the brain.
//!
//! - [`ccd`]: coil models as SimNIBS keeps them (`.ccd`: magnetic dipoles in the coil's frame,
//!   with the stimulator's greatest dI/dt), read from their text;
//! - [`sphere`]: the field of those dipoles inside a conducting sphere (Heller and van
//!   Hulsteyn 1992), exact for the sphere and independent of its conductivity, a point at a
//!   time, allocating nothing;
//! - [`fit`]: the sphere nearest a patch of points (least squares);
//! - [`dose`]: the dose at a target against the one planned, for any coil pose;
//! - [`plans`]: a run's plans, one per goal it may hold, measured against by the goal's pose;
//! - [`local`]: the sphere a head is taken to be under the coil (fitted to the scalp near it,
//!   as local-sphere methods do), for any head shape.
//!
//! **Limits.** No I/O: callers read files and hand over their text. Metres, seconds, amperes
//! inside; a `.ccd` is in metres already. The sphere model ignores the head's folds: the
//! field's size at a cortical target is within the error local-sphere models are known for
//! (tens of percent against FEM), while its change with the coil's pose, which the loop acts
//! on, is far better.

pub mod ccd;
pub mod dose;
pub mod error;
pub mod fit;
pub mod local;
pub mod plans;
pub mod sphere;
#[cfg(test)]
mod test_coil;

pub use ccd::{DipoleCoil, parse_ccd};
pub use dose::{Along, DoseMeter, DoseModel, PlannedDose};
pub use error::EfieldError;
pub use fit::fit_sphere;
pub use local::{FIT_RADIUS_M, LocalSphere, local_sphere};
pub use plans::{Dose, DosePlanError, DosePlans};
pub use sphere::{PlacedCoil, Sphere};
