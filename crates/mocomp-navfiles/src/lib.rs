//! The navigators' files, as text: what other navigation systems export is read into coil
//! poses and landmarks ([`read`]), and a session's pulses are written for a lab's tools
//! ([`bids`]: NIBS-BIDS; [`localite`]: Localite's trigger markers, which [`read`] reads back).
//!
//! No I/O: callers read and write the files, so every format is tested, fuzzed and golden-checked
//! on strings. Poses are SimNIBS's coil convention in the image's RAS frame (+z into the head,
//! +y pointing away from the handle), metres; the files' own millimetres are converted at the
//! edge, here.

pub mod bids;
pub mod localite;
pub mod read;

/// A file that is not what it should be: the message names the file, and the line, item or
/// value where it went wrong. Bad input, as the caller's configuration or option is.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct FileError(pub String);
