//! Azure Kinect depth cameras (and Orbbec's Femto cameras through Orbbec's k4a-compatible
//! library) and their `.mkv` recordings, for the paper's IR + depth tracking path, live.
//!
//! The SDK (`libk4a`, `libk4arecord` 1.4, MIT) is opened at run time ([`Sdk::load`]): mocomp
//! builds and runs without it, and a missing SDK is an error that says how to install it. Debian
//! has no package; the PyPI wheel `pyk4a-bundle` ships the SDK's own libraries.
//!
//! - [`Playback`]: a recording's configuration, the depth camera's factory calibration as
//!   [`mocomp_vision::Intrinsics`] (rational Brown–Conrady), its IR and depth images with their
//!   device timestamps; a truncated file is an error naming how far it got.
//! - [`Device`]: a live camera by serial number, its calibration per depth mode, its captures;
//!   an unplugged camera is [`K4aError::DeviceLost`].
//! - [`Recorder`]: recordings written by the SDK's own recorder (user captures, calibration
//!   attached), which its playback reads as a camera's.
//! - [`clock`]: device timestamps on the host's clock, dropped frames. Pure.
//!
//! `unsafe` lives in two modules only: `ffi` (the C types and the function table) and
//! `handles` (each SDK handle as an owned value with safe methods).
//!
//! **Limits.** Opens the SDK at run time and never links it; without the SDK every call is a clear
//! error, not a missing symbol.

mod calibration;
pub mod clock;
mod device;
mod error;
mod ffi;
mod handles;
pub mod modes;
mod playback;
mod record;

pub use device::Device;
pub use error::INSTALL_HINT;
pub use error::K4aError;
pub use handles::{Capture16, Image16, Sdk};
pub use modes::DepthMode;
pub use playback::{Playback, RecordingInfo};
pub use record::Recorder;
