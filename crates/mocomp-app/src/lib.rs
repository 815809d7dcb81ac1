//! The mocomp application core. A session starts from one configuration ([`config::Config`],
//! loaded and checked once into a [`config::Setup`]), connects the world it describes
//! ([`world::World`]: a UR or an in-process simulated controller, an OpenIGTLink tracker or the
//! simulated one), and does one job on it: the live loop ([`live`]), a calibration collection
//! ([`robot::collect`]) or teaching the goal ([`robot::teach`]). Front ends (the `mocomp` CLI, the
//! web console, the ROS 2 bridge) parse their input, call these and present the results; none of
//! them computes.
//!
//! The modules, grouped by what a clinic does with them, each group using only those above it:
//! [`files`] (read under a limit, written whole, the caches); [`config`] (the file's sections,
//! what is loaded from them, its template and reference); [`camera`] (a depth camera as a
//! tracker, frames and recordings); [`world`] (what a session connects to); [`navigation`] (the
//! head, its EEG positions, targets placed and imported, the arm's reach); [`registration`] (the
//! pointer, the registration live and rehearsed, its report and gate); [`live`] (the loop, its
//! logger, the clinical session around it, its front ends: ROS 2 and 3D Slicer); [`robot`]
//! (calibration collection, teaching, the servo check); [`demo`] (the built-in world's
//! experiment); and, alone, `blame`, `listen`, `pose_lines`, `efield_calc`, `session_export`.
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

pub mod blame;
pub mod camera;
pub mod config;
pub mod demo;
pub mod efield_calc;
pub mod files;
pub mod listen;
pub mod live;
pub mod navigation;
pub mod pose_lines;
pub mod registration;
pub mod robot;
pub mod session_export;
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

/// An error and each of its causes in one line (`what: why: why`), for a page that shows no
/// chain: a console saying only "calibrate collect stopped the robot" leaves the operator
/// without the reason. A cause whose words its error already says is not said twice.
pub fn in_full(e: &(dyn std::error::Error + 'static)) -> String {
    let mut out = e.to_string();
    for cause in std::iter::successors(e.source(), |c| c.source()) {
        let words = cause.to_string();
        if !words.is_empty() && !out.contains(&words) {
            out.push_str(": ");
            out.push_str(&words);
        }
    }
    out
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

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::{AppError, in_full};

    /// The console's failure line carries the reason, however deep, once.
    #[test]
    fn an_error_in_full_names_every_cause_once() {
        let io = std::io::Error::new(std::io::ErrorKind::TimedOut, "no robot state for 250 ms");
        let inner = AppError::failed("the move to pose 5 did not arrive", io);
        let outer = AppError::failed("calibrate collect stopped the robot", inner);
        assert_eq!(
            in_full(&outer),
            "calibrate collect stopped the robot: the move to pose 5 did not arrive: \
             no robot state for 250 ms"
        );
        // A message that already says its cause's words does not repeat them.
        let io = std::io::Error::other("disk full");
        let said = AppError::failed("writing the log: disk full", io);
        assert_eq!(in_full(&said), "writing the log: disk full");
        assert_eq!(in_full(&AppError::Refused("no".into())), "no");
    }
}
