//! The simulated world mocomp runs on without hardware:
//! - [`motion`]: head-motion generators (still, drift, nods and turns, smooth random motion),
//!   deterministic functions of time.
//! - [`tracker`]: a tracker model (rate, latency, noise in position and rotation, dropouts,
//!   outliers), pure and steppable, and [`tracker::TrackerServer`], which runs it in real time
//!   and serves the markers over OpenIGTLink as a PLUS server would.
//! - [`config`]: the experiment's TOML configuration file (`mocomp demo --config`).
//! - [`experiment`]: the paper's two-robot experiment, with hand-eye calibration in the loop and
//!   two controllers (a model of the paper's pipeline, and mocomp's loop) on the same trajectory.

pub mod baseline;
pub mod config;
pub mod experiment;
pub mod motion;
pub mod trace;
pub mod tracker;

pub use motion::{HeadMotion, MotionError};
pub use tracker::{
    Observation, TrackedMarker, TrackerError, TrackerModel, TrackerServer, TrackerSim,
};
