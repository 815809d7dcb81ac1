//! What can go wrong with a depth camera or its recording.

/// How to get the SDK, for the error that says it is missing.
pub const INSTALL_HINT: &str = "install the Azure Kinect SDK 1.4 (Microsoft's libk4a1.4 and \
     libk4a1.4-dev packages), or `pip install pyk4a-bundle` and point tracker.k4a.sdk_dir (or \
     MOCOMP_K4A_SDK_DIR) at its pyk4a_bundle.libs directory";

/// An error from the SDK, a recording or a device; each names what it concerns.
#[derive(Debug, thiserror::Error)]
pub enum K4aError {
    /// The SDK's libraries are not there (or lack a function).
    #[error("the Azure Kinect SDK is not available ({tried}: {detail}); {hint}", hint = INSTALL_HINT)]
    SdkMissing {
        /// The directory or library tried.
        tried: String,
        /// The dynamic loader's message.
        detail: String,
    },
    /// An SDK call failed.
    #[error("the Azure Kinect SDK refused: {call} failed")]
    Call {
        /// The function.
        call: &'static str,
    },
    /// A recording could not be opened or created.
    #[error("{path}: {detail}")]
    Recording {
        /// The file.
        path: String,
        /// Why.
        detail: String,
    },
    /// A recording ended in the middle of a capture (truncated or damaged).
    #[error(
        "{path}: damaged after {captures} captures (at {after_usec} µs): the SDK cannot read the next one (a truncated or corrupt file)"
    )]
    Damaged {
        /// The file.
        path: String,
        /// Captures read before.
        captures: u64,
        /// The last capture's device timestamp, µs.
        after_usec: u64,
    },
    /// An image that is not what it says (format, size, buffer).
    #[error("{what}: {detail}")]
    BadImage {
        /// Which image.
        what: &'static str,
        /// What is wrong.
        detail: String,
    },
    /// A calibration the lens model cannot take.
    #[error("calibration: {0}")]
    Calibration(String),
    /// A mode or frame rate the device or recording does not have.
    #[error("{0}")]
    Mode(String),
    /// A bad argument (a path with a NUL, a capture of the wrong size).
    #[error("{0}")]
    BadArgument(String),
    /// No device, or not the one asked for.
    #[error("{0}")]
    NoDevice(String),
    /// The device stopped answering (unplugged, or its USB link failed).
    #[error(
        "the depth camera stopped delivering captures (unplugged, or its USB connection failed)"
    )]
    DeviceLost,
}
