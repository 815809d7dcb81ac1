//! The mocomp application core. A session starts from one configuration ([`config::Config`],
//! loaded and checked once into a [`config::Setup`]), connects the world it describes
//! ([`world::World`]: a UR or an in-process simulated controller, an OpenIGTLink tracker or the
//! simulated one), and does one job on it: the live loop ([`live`]), a calibration collection
//! ([`collect`]) or teaching the goal ([`teach`]). Front ends (the `mocomp` CLI, the web console,
//! the ROS 2 bridge) parse their input, call these and present the results; none of them computes.
//!
//! I/O lives here (sockets, threads, files, the wall clock); the math it calls does none.
//!
//! **Limits.** No command-line parsing and no printing to the terminal: it returns reports and
//! errors, and the binary prints them. The compensation itself is mocomp-control's; the
//! application only connects, runs and records it.

/// Returns an [`AppError::Refused`] with a formatted message.
macro_rules! refuse {
    ($($arg:tt)*) => {
        return Err($crate::AppError::Refused(format!($($arg)*)))
    };
}

pub mod affine_file;
pub mod blame;
pub mod cache_files;
pub mod camera;
pub mod camera_k4a;
pub mod camera_sim;
pub mod capped_file;
pub mod coil_config;
pub mod collect;
pub mod config;
pub mod config_check;
pub mod config_file;
pub mod config_reference;
pub mod demo_options;
pub mod demo_record;
pub mod demo_run;
pub mod eeg_report;
pub mod efield_calc;
pub mod experiment_config;
pub mod field_cache;
pub mod frames;
pub mod head_file;
pub mod k4a;
pub mod k4a_record;
pub mod listen;
pub mod live;
pub mod live_log;
pub mod live_session;
pub mod navigation;
pub mod placement;
pub mod placement_report;
pub mod pointer;
pub mod pose_lines;
pub mod register;
pub mod register_open;
pub mod register_report;
pub mod registration_config;
pub mod registration_file;
pub mod registration_gate;
pub mod rehearsal;
pub mod ros2;
pub mod scalp_cache;
pub mod servo_check;
pub mod session_export;
pub mod session_link;
pub mod session_wiring;
pub mod slicer;
pub mod target_import;
pub mod target_report;
pub mod targets;
pub mod teach;
pub mod tuning;
pub mod whole_file;
pub mod world;

/// The experiment, the driver and the calibration procedure, from their own crate (the live
/// session uses the driver and the calibration procedure too).
pub use mocomp_experiment::{experiment, session_plan};

/// The front ends' contract, from its own crate (the experiment speaks it too).
pub use mocomp_frontend as frontend;
/// The camera pipeline's link to the front ends.
pub use mocomp_frontend::vision as camera_link;

impl From<mocomp_frontend::FrontendError> for AppError {
    fn from(e: mocomp_frontend::FrontendError) -> Self {
        use mocomp_frontend::FrontendError as F;
        match e {
            F::Refused(m) => Self::Refused(m),
            F::Config(m) => Self::Config(m),
            e @ F::Vision { .. } => Self::failed(e.to_string(), e),
        }
    }
}

/// Boxed cause of an [`AppError::Failed`].
pub type Cause = Box<dyn std::error::Error + Send + Sync + 'static>;

/// What went wrong in a session.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    /// The configuration (or an option standing for one of its keys) is bad; the message names
    /// the file and the key. Bad input: nothing was started.
    #[error("{0}")]
    Config(String),
    /// A well-formed request the world refused: an unsafe goal, a robot that stopped, a marker
    /// out of view.
    #[error("{0}")]
    Refused(String),
    /// Doing `what` failed; the cause (kept as the source) says why, and whether the input or
    /// the world was at fault.
    #[error("{what}")]
    Failed {
        /// What was being done (a file, a connection, a step).
        what: String,
        /// Why it failed.
        #[source]
        source: Cause,
    },
}

/// A navigator's file that is not what it should be is bad input, as the configuration is.
impl From<mocomp_navfiles::FileError> for AppError {
    fn from(e: mocomp_navfiles::FileError) -> Self {
        Self::Config(e.0)
    }
}

impl AppError {
    /// A failure of `what`, caused by `source`.
    pub fn failed(what: impl Into<String>, source: impl Into<Cause>) -> Self {
        Self::Failed {
            what: what.into(),
            source: source.into(),
        }
    }
}

/// Adds what was being done to an error, keeping it as the source.
pub trait Context<T> {
    /// On error: [`AppError::Failed`] with `what()` and the error as its source.
    fn what<S: Into<String>>(self, what: impl FnOnce() -> S) -> Result<T, AppError>;
}

impl<T, E: Into<Cause>> Context<T> for Result<T, E> {
    fn what<S: Into<String>>(self, what: impl FnOnce() -> S) -> Result<T, AppError> {
        self.map_err(|e| AppError::failed(what(), e))
    }
}
