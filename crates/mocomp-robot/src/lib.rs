//! The robot as the control loop sees it, apart from any protocol.
//!
//! - [`command`]: the [`Robot`] trait (servo, move, speed, stop, keep-alive, free-drive) and
//!   the checked parameters of a servo stream;
//! - [`state`]: the [`RobotState`] an arm reports each controller cycle, its modes
//!   ([`RobotMode`], [`SafetyMode`], [`RuntimeState`]), the [`RobotFault`]s that forbid a command,
//!   and where its wrench comes from ([`ForceSource`]);
//! - [`mode`]: the control program's modes, which an implementation reports in
//!   [`RobotState::program_mode`];
//! - [`error`]: [`RobotError`], a refused command, with an implementation's own error as its
//!   source.
//!
//! The control loop (`mocomp-control`) depends on this crate and not on a protocol; the UR client
//! (`mocomp-ur`) implements [`Robot`] over RTDE, the test kit in memory. Units: radians, metres,
//! seconds; TCP poses as `base_from_tcp` isometries.

pub mod command;
pub mod error;
pub mod state;

/// The control program's modes, as [`RobotState::program_mode`] reports them (the UR program
/// writes them to `output_int_register_24`).
pub mod mode {
    /// Not running.
    pub const NOT_RUNNING: i32 = 0;
    /// Idle.
    pub const IDLE: i32 = 1;
    /// Servoing.
    pub const SERVO: i32 = 2;
    /// Executing a MOVEJ.
    pub const MOVING: i32 = 3;
    /// Speed control.
    pub const SPEED: i32 = 4;
    /// Decelerating after STOPJ.
    pub const STOPPING: i32 = 5;
    /// In free-drive.
    pub const FREEDRIVE: i32 = 6;
}

pub use command::{Robot, ServoParams};
pub use error::{RobotError, check_range};
pub use state::{ForceSource, RobotFault, RobotMode, RobotState, RuntimeState, SafetyMode};
