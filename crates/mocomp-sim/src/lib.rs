//! The simulated world mocomp runs on without hardware:
//! - [`motion`]: head-motion generators (still, drift, nods and turns, smooth random motion),
//!   deterministic functions of time.
//! - [`tracker`]: a tracker model (rate, latency, noise in position and rotation, dropouts,
//!   outliers), pure and steppable, and [`tracker::TrackerServer`], which runs it in real time
//!   and serves the markers over OpenIGTLink as a PLUS server would.
//!
//! The paper's two-robot experiment that runs on it is `mocomp_app::experiment`.
//!
//! **Limits.** Simulates the world, never the controller under test: it does not use
//! mocomp-control's loop, only its geometric models, so a bug there is not hidden by the same bug
//! here.

pub mod contact;
pub mod motion;
pub mod trace;
pub mod tracker;

pub use motion::{HeadMotion, MotionError};
pub use tracker::{
    Observation, TrackedMarker, TrackerError, TrackerModel, TrackerServer, TrackerSim,
};
