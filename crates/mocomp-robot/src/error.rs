//! Why a robot did not take a command.

use crate::state::RobotFault;

/// A command the robot did not take. An implementation's own failure (a socket, a codec) is the
/// source of [`RobotError::Link`], so the loop can name it without knowing the protocol.
#[derive(Debug, thiserror::Error)]
pub enum RobotError {
    /// The robot is in a state that forbids the command.
    #[error("command refused: {0}")]
    Fault(RobotFault),
    /// A command argument is out of range.
    #[error("{field} = {value} is outside [{min}, {max}]")]
    OutOfRange {
        /// Argument name.
        field: &'static str,
        /// Given value.
        value: f64,
        /// Smallest allowed.
        min: f64,
        /// Largest allowed.
        max: f64,
    },
    /// The link to the robot failed (the implementation's error is the source).
    #[error("robot link: {0}")]
    Link(#[source] Box<dyn std::error::Error + Send + Sync + 'static>),
}

/// `value` within `[min, max]` and finite, or [`RobotError::OutOfRange`] naming `field`.
pub fn check_range(field: &'static str, value: f64, min: f64, max: f64) -> Result<(), RobotError> {
    if value.is_finite() && value >= min && value <= max {
        Ok(())
    } else {
        Err(RobotError::OutOfRange {
            field,
            value,
            min,
            max,
        })
    }
}
