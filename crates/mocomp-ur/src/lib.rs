//! Universal Robots interfaces for mocomp.
//!
//! - [`codec`], [`types`]: the RTDE wire format (TCP 30004) and the controller's typed variable
//!   table, without I/O; [`connection`]: a blocking RTDE client connection (protocol 2 with
//!   fallback to 1, recipes, start/pause, text messages).
//! - [`dashboard`]: the dashboard client (TCP 29999): power, brakes, play/stop, modes, protective
//!   stop unlock, remote-control check.
//! - [`program`]: mocomp's resident URScript control program and **its register protocol** (in
//!   the external-client register range 24–47, with an RTDE watchdog).
//! - [`recovery`]: what a re-arm does after the controller stopped the arm (reconnect, unlock a
//!   protective stop, restart the program, or refuse with what the operator must do), decided
//!   without sockets.
//! - [`client`]: [`UrRobot`], the implementation of `mocomp_robot`'s [`Robot`] over RTDE (state
//!   on its own thread, newest state readable without blocking or locks).
//!
//! Units: radians, metres, seconds everywhere; TCP poses as `base_from_tcp` isometries.
//!
//! **Limits.** Knows no head, no tracker and no loop: the robot's protocols and its recovery only.
//! Every received byte is hostile (sizes before allocation).

pub mod client;
pub mod codec;
pub mod connection;
pub mod dashboard;
pub mod error;
pub mod line;
pub mod program;
pub mod recovery;
pub mod types;

pub use client::{UrConfig, UrRobot};
pub use codec::{ControllerVersion, Recipe};
pub use error::{RtdeError, UrError};
// The interface UrRobot implements, for callers that hold one.
pub use mocomp_robot::{
    ForceSource, Robot, RobotError, RobotFault, RobotMode, RobotState, RuntimeState, SafetyMode,
    ServoParams,
};
pub use types::{DataType, Value};
