//! The simulated world mocomp runs on without hardware:
//! - [`motion`]: head-motion generators (still, drift, nods and turns, smooth random motion),
//!   deterministic functions of time.
//! - [`tracker`]: a tracker model (rate, latency, noise in position and rotation, dropouts,
//!   outliers), pure and steppable, and [`tracker::TrackerServer`], which runs it in real time
//!   and serves the markers over OpenIGTLink as a PLUS server would.
//!
//! - [`skin`]: the patient's skin against the head model (a smooth random field along its
//!   normal), and [`operator`]: a simulated operator with a tracked pointer, pivoting it, touching
//!   landmarks and sweeping the scalp as asked, for rehearsing a registration.
//!
//! The paper's two-robot experiment that runs on it is `mocomp_app::experiment`.
//!
//! **Limits.** Simulates the world, never the controller under test: it does not use
//! mocomp-control's loop, only its geometric models, so a bug there is not hidden by the same bug
//! here.

pub mod contact;
pub mod motion;
pub mod operator;
pub mod skin;
pub mod trace;
pub mod tracker;

pub use motion::{HeadMotion, MotionError};
pub use tracker::{
    Observation, TrackedMarker, TrackerError, TrackerModel, TrackerServer, TrackerSim,
};
