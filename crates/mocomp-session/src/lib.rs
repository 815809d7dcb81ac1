//! The clinical session around the compensation loop (issue 20): what a TMS session needs besides
//! keeping the coil on its goal.
//!
//! - [`gate`]: the on-target gate. A pulse is allowed only while the measured coil has stayed
//!   within its tolerance of the target for a dwell time, and never while the coil travels.
//! - [`grid`]: a grid of targets around one, on the head model's surface, each coil axis along
//!   the surface normal (motor mapping walks such a grid around the hotspot).
//! - [`drift`]: whether the tracker and the robot's base are still where the calibration says.
//! - [`targets`]: the session's named targets and their file.
//! - [`session`]: the selected target, the gate on each cycle, the pulses and the drift
//!   monitor's latched verdict, together beside the loop.
//! - [`history`]: the robot's recent joints, to compare a marker sample with the robot where it
//!   was when the sample was acquired.
//! - [`pulses`]: the pulse log, one CSV row per pulse: its UTC time, the coil's error, its pose
//!   on the image and distance to the scalp, the stimulator's output, the gate; read back.
//!
//! Pure logic: no robot, no socket, no clock (the targets file is parsed and printed, the pulse
//! log written to a writer the caller gives).
//!
//! **Limits.** Pure: no I/O, no robot, no socket; the application feeds it cycle records and robot
//! inputs, and carries its decisions out.

pub mod drift;
pub mod gate;
pub mod grid;
pub mod history;
pub mod pulses;
pub mod session;
pub mod targets;

pub use drift::{Drift, DriftMonitor, DriftParams};
pub use gate::{Gate, GateEvent, GateInputs, GateParams, GateState, Shut};
pub use grid::{GridError, GridParams, GridPoint, grid_around};
pub use history::JointHistory;
pub use pulses::{
    Pulse, PulseLog, PulseLogError, Recorder, iso8601, matsimnibs, parse_iso8601, read_log,
};
pub use session::{Announced, PulseAt, Session, SessionParams, Step, shut_reason};
pub use targets::{Target, Targets, TargetsError};
