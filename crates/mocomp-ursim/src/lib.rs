//! A simulated Universal Robots controller that real UR clients accept.
//!
//! [`Sim`] serves, on one address (its own loopback address per robot: 127.0.0.2, 127.0.0.3, …,
//! so several run side by side on the standard ports):
//! - **RTDE** (30004): protocol 2 and 1, controller version, output recipes with the exact
//!   controller types of every variable at up to the controller rate (125 Hz CB3, 500 Hz
//!   e-Series), input recipes numbered 1, 2, … per connection with `NOT_FOUND` and `IN_USE`
//!   (input ownership across connections, released on disconnect), start/pause, text messages;
//! - the **dashboard** (29999), with the replies of §3.3 of the team's reference;
//! - the **script ports** (30001, 30002, 30003): complete `def …():`/`end` programs are loaded;
//!   mocomp's control program and ur_rtde's `rtde_control` script run natively (their register
//!   protocols, not a URScript interpreter); other programs are logged and not run.
//!
//! [`cell`]: the cell's own events (a protective stop, the emergency stop), as text lines from
//! whoever stands for the room.
//!
//! The [`controller::Controller`] steps the joints every controller period. With
//! [`SimClock::RealTime`] a thread steps it on the machine's clock; with [`SimClock::Stepped`]
//! the owner calls [`Sim::step`], so tests and the demo run deterministically while clients still
//! talk TCP.
//!
//! **Limits.** A test and demonstration controller, never a safety reference: it models what UR's
//! controllers do to a client (timing, registers, faults), not their certified safety system.

pub mod cell;
pub mod controller;
mod server;

pub use controller::{
    Bank, Controller, ControllerConfig, DEFAULT_TCP_FORCE_LIMIT_N, Io, SimEvent, ToolLoad,
    ToolLoadFn,
};
pub use server::{Ports, Sim, SimAddrs, SimClock, SimConfig, SimError, SimHandle, SimStats};
