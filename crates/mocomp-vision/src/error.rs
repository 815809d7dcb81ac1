//! The error type of `mocomp-vision`. Errors are for bad input (buffers, files, parameters); a
//! frame in which the marker is not found is a result, not an error.

/// What can go wrong in the vision pipeline.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum VisionError {
    /// A buffer's length does not match the frame size.
    #[error("{what}: {len} pixels, expected {width}×{height} = {}", width * height)]
    BufferSize {
        /// Which buffer ("IR image", "depth image").
        what: &'static str,
        /// Its length.
        len: usize,
        /// Expected width.
        width: usize,
        /// Expected height.
        height: usize,
    },
    /// IR and depth images of different sizes, or not the size of the intrinsics.
    #[error("{what} is {got_w}×{got_h}, expected {want_w}×{want_h}")]
    SizeMismatch {
        /// Which image.
        what: String,
        /// Its width.
        got_w: u32,
        /// Its height.
        got_h: u32,
        /// Expected width.
        want_w: u32,
        /// Expected height.
        want_h: u32,
    },
    /// An empty image.
    #[error("{what} is empty (0 pixels)")]
    Empty {
        /// Which image.
        what: String,
    },
    /// An image that is not 16-bit grayscale.
    #[error("{what}: expected a 16-bit grayscale PNG, found {found}")]
    PixelFormat {
        /// Which image.
        what: String,
        /// What it is.
        found: String,
    },
    /// An image that cannot be decoded.
    #[error("{what}: {message}")]
    Decode {
        /// Which image.
        what: String,
        /// The decoder's message.
        message: String,
    },
    /// A marker geometry that cannot be used.
    #[error("marker geometry{}: {message}", location.as_ref().map(|l| format!(" ({l})")).unwrap_or_default())]
    Geometry {
        /// Where in the file (line, section or byte offset), when known.
        location: Option<String>,
        /// What is wrong.
        message: String,
    },
    /// Intrinsics or tracking parameters that cannot be used.
    #[error("{what}: {message}")]
    Config {
        /// Which file or field.
        what: String,
        /// What is wrong.
        message: String,
    },
}
