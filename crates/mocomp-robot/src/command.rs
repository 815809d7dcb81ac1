//! What the control loop commands: the [`Robot`] trait (servoj, movej, speedj, stopj, the
//! keep-alive, free-drive) and the parameters of `servoj`, checked.

use crate::error::{RobotError, check_range};
use crate::state::RobotState;

/// The parameters of `servoj`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoParams {
    /// The time each target controls the robot, s (the controller period: 0.002 / 0.008).
    pub time_s: f64,
    /// Lookahead time, s, in [0.03, 0.2].
    pub lookahead_s: f64,
    /// Proportional gain, in [100, 2000].
    pub gain: f64,
}

impl ServoParams {
    /// ur_rtde's example values (lookahead 0.1 s, gain 300) for a controller period.
    pub fn for_period(period_s: f64) -> Self {
        Self {
            time_s: period_s,
            lookahead_s: 0.1,
            gain: 300.0,
        }
    }

    /// Checks the ranges the controller accepts (URScript manual, ur_rtde's limits).
    pub fn validate(&self) -> Result<(), RobotError> {
        check_range("servo time_s", self.time_s, 0.001, 1.0)?;
        check_range("servo lookahead_s", self.lookahead_s, 0.03, 0.2)?;
        check_range("servo gain", self.gain, 100.0, 2000.0)
    }
}

/// A robot the control loop can drive. State arrives on its own; reading it never blocks.
pub trait Robot {
    /// The newest state, or `None` before the first.
    fn state(&self) -> Option<RobotState>;
    /// How many states have arrived (grows by one per controller cycle received).
    fn state_count(&self) -> u64;
    /// Blocks until more than `seen` states have arrived, or `timeout` has passed; returns
    /// [`Robot::state_count`]. This default polls every 100 µs; a client with a receive thread
    /// wakes the waiting thread instead, so a loop paced by the robot neither spins nor oversleeps.
    fn wait_for_state(&mut self, seen: u64, timeout: std::time::Duration) -> u64 {
        let end = std::time::Instant::now() + timeout;
        loop {
            let n = self.state_count();
            if n != seen || std::time::Instant::now() >= end {
                return n;
            }
            std::thread::sleep(std::time::Duration::from_micros(100));
        }
    }
    /// The controller period, s.
    fn period_s(&self) -> f64;
    /// Streams one servo target (call every cycle). Returns the command's sequence number.
    fn servo(&mut self, q: &[f64; 6], params: &ServoParams) -> Result<i32, RobotError>;
    /// Starts a point-to-point joint move (`movej`); its completion shows as
    /// [`RobotState::move_done_seq`] reaching the returned sequence number.
    fn move_joints(&mut self, q: &[f64; 6], speed: f64, accel: f64) -> Result<i32, RobotError>;
    /// Joint speed control (`speedj`), until the next command or stop.
    fn speed_joints(&mut self, qd: &[f64; 6], accel: f64) -> Result<i32, RobotError>;
    /// Decelerates to standstill (`stopj`). Sent even when the robot reports a fault.
    fn stop(&mut self, decel: f64) -> Result<i32, RobotError>;
    /// Repeats the last command (keeps the watchdog fed while nothing new is commanded).
    fn keep_alive(&mut self) -> Result<(), RobotError>;
    /// Free-drive: the arm yields to a hand for as long as this is sent each cycle (its
    /// keep-alive is the dead-man switch); any other command ends it.
    fn freedrive(&mut self) -> Result<i32, RobotError>;
}
