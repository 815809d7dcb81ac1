//! Errors of the UR interfaces.

use crate::types::DataType;

/// An RTDE encoding or decoding error.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum RtdeError {
    /// A frame's size field is below the header size: the stream is out of step.
    #[error("RTDE frame at byte {offset} declares size {size}, below the 3-byte header")]
    BadFrameSize {
        /// Byte offset of the frame in the stream.
        offset: u64,
        /// The declared size.
        size: usize,
    },
    /// A package whose payload does not fit its type's layout.
    #[error("malformed RTDE package '{kind}': {what}")]
    Malformed {
        /// Package type character.
        kind: char,
        /// What is wrong.
        what: String,
    },
    /// A package type RTDE does not define.
    #[error("unknown RTDE package type 0x{0:02x}")]
    UnknownType(u8),
    /// A package larger than 65,535 bytes.
    #[error("RTDE package of {0} bytes exceeds the 65,535-byte frame limit")]
    TooLarge(usize),
    /// A length-prefixed text longer than 255 bytes.
    #[error("RTDE text field {field} is {len} bytes, the limit is 255")]
    FieldTooLong {
        /// Field name.
        field: &'static str,
        /// Its length.
        len: usize,
    },
    /// Variables the controller does not know.
    #[error("the controller does not know RTDE variable(s) {names} (NOT_FOUND)")]
    NotFound {
        /// Comma-separated names.
        names: String,
    },
    /// Inputs owned by another client or a fieldbus interface.
    #[error(
        "RTDE input(s) {names} are in use by another RTDE client or a fieldbus interface \
         (EtherNet/IP, PROFINET, MODBUS) (IN_USE)"
    )]
    InUse {
        /// Comma-separated names.
        names: String,
    },
    /// A type name RTDE does not define.
    #[error("the controller answered type {type_name:?} for RTDE variable {name}")]
    UnknownDataType {
        /// Variable.
        name: String,
        /// The type word received.
        type_name: String,
    },
    /// A setup reply with a different number of entries than requested.
    #[error("recipe has {requested} variables but {answered} were given")]
    RecipeMismatch {
        /// Variables in the recipe.
        requested: usize,
        /// Types or values given.
        answered: usize,
    },
    /// A data package of the wrong size for its recipe.
    #[error("data package for recipe {id} has {got} bytes, the recipe needs {expected}")]
    DataSize {
        /// Recipe id.
        id: u8,
        /// Bytes received.
        got: usize,
        /// Bytes expected.
        expected: usize,
    },
    /// A value of the wrong type for its variable.
    #[error("RTDE variable {name} is {expected}, the value given is {got}")]
    TypeMismatch {
        /// Variable.
        name: String,
        /// Its type.
        expected: DataType,
        /// The value's type.
        got: DataType,
    },
}

/// An error talking to a robot (or to the simulator) over the network.
#[derive(Debug, thiserror::Error)]
pub enum UrError {
    /// A socket operation failed. (The cause is part of the message, not a separate source,
    /// so error chains print it once.)
    #[error("{context}: {cause}")]
    Io {
        /// What we were doing (names the interface and address).
        context: String,
        /// The cause.
        cause: std::io::Error,
    },
    /// The peer sent bytes that are not valid RTDE.
    #[error("{context}: {cause}")]
    Rtde {
        /// What we were doing.
        context: String,
        /// The cause.
        cause: RtdeError,
    },
    /// No answer in time.
    #[error("timed out after {ms} ms waiting for {what}")]
    Timeout {
        /// What we waited for.
        what: String,
        /// How long, milliseconds.
        ms: u128,
    },
    /// The controller refused a request.
    #[error("the controller refused {what}")]
    Refused {
        /// The request.
        what: String,
    },
    /// The controller runs no RTDE protocol version we speak.
    #[error("the controller accepts neither RTDE protocol version 2 nor 1")]
    NoProtocol,
    /// A dashboard reply we did not expect.
    #[error("dashboard command {command:?} answered {reply:?} (expected {expected})")]
    Dashboard {
        /// The command sent.
        command: String,
        /// The reply received.
        reply: String,
        /// What a successful reply looks like.
        expected: &'static str,
    },
    /// The connection closed.
    #[error("{what}: the connection was closed")]
    Closed {
        /// Which interface.
        what: String,
    },
    /// The robot did not take the command: a fault forbids it, or an argument is out of range.
    /// The robot's own error, so the loop's `RobotError` and this one never disagree (only its
    /// `Fault` and `OutOfRange` are made here).
    #[error(transparent)]
    Robot(#[from] mocomp_robot::RobotError),
}

impl UrError {
    pub(crate) fn io(context: impl Into<String>, cause: std::io::Error) -> UrError {
        UrError::Io {
            context: context.into(),
            cause,
        }
    }
}

pub(crate) fn range(field: &'static str, value: f64, min: f64, max: f64) -> Result<(), UrError> {
    Ok(mocomp_robot::check_range(field, value, min, max)?)
}

/// What the loop sees of a UR failure: the robot's own refusal as it is, the rest is the
/// link's, with this error as its source.
impl From<UrError> for mocomp_robot::RobotError {
    fn from(e: UrError) -> Self {
        match e {
            UrError::Robot(e) => e,
            other => Self::Link(Box::new(other)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_robot::{RobotError, RobotFault};
    use std::error::Error;

    #[test]
    fn the_loop_sees_a_fault_and_a_range_as_such_and_the_rest_as_the_link_with_its_cause() {
        let e: RobotError = UrError::Robot(RobotError::Fault(RobotFault::ProtectiveStop)).into();
        assert!(matches!(e, RobotError::Fault(RobotFault::ProtectiveStop)));
        let e: RobotError = range("servo gain", 5.0, 100.0, 2000.0).unwrap_err().into();
        assert!(
            matches!(
                e,
                RobotError::OutOfRange {
                    field: "servo gain",
                    ..
                }
            ),
            "{e}"
        );
        let cause = std::io::Error::new(std::io::ErrorKind::BrokenPipe, "peer gone");
        let e: RobotError = UrError::io("sending a command to 127.0.0.1", cause).into();
        assert!(matches!(e, RobotError::Link(_)));
        let src = e.source().expect("the UR error is the source");
        // The socket's cause is part of the UR error's message, so a chain prints it once.
        assert_eq!(src.to_string(), "sending a command to 127.0.0.1: peer gone");
    }
}
