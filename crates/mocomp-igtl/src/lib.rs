//! OpenIGTLink for mocomp: how tracker poses arrive from PLUS / 3D Slicer set-ups (and how mocomp
//! serves its own).
//!
//! - [`codec`]: the 58-byte header (versions 1 and 2, with extended header and metadata),
//!   CRC-64/ECMA-182 verified on receipt, TRANSFORM, POSITION, TDATA, STATUS, STRING and the
//!   GET_/STT_/STP_/RTS_ queries; unknown types skipped by their size; a body-size limit; a
//!   streaming decoder for bytes arriving in pieces. No I/O.
//! - [`client`]: a blocking TCP client on its own thread that reconnects with backoff, counts
//!   everything, maps message timestamps onto the monotonic clock, and publishes the newest pose
//!   of a device lock-free to an [`client::IgtlPoseSource`].
//! - [`offset`]: a sender's clock against ours from the smallest delay, re-based when it steps.
//! - [`server`]: streams messages to any number of clients, answers GET_ queries, starts and
//!   stops TDATA streams, and drops a slow client without stalling the others.
//!
//! **Limits.** Knows no robot and no loop: bytes to messages, a client and a server. Every
//! received byte is hostile: sizes are limited before allocation, errors name the byte offset.

pub mod client;
pub mod codec;
pub mod message;
pub mod name;
pub mod offset;
pub mod server;
pub mod timestamp;

pub use codec::{DecodeError, Decoder, decode, encode};
pub use message::{Body, Message, MetaEntry};
pub use name::{DeviceName, TypeName};
pub use timestamp::Timestamp;
