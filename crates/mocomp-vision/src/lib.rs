//! Fiducial tracking from IR + depth frames (the seed paper's Kinect path, section IV), on
//! buffers:
//!
//! 1. threshold the IR image, gate by the depth range (depth 0 is kept: fiducials read 0), keep
//!    the scan area ([`blobs`]);
//! 2. label 8-connected blobs in one pass with area, bounding box and weighted centroid, filter by
//!    area and edge contact;
//! 3. depth of each blob from a ring just outside its bounding box (median of valid readings);
//! 4. back-project the undistorted centroid ([`intrinsics`]);
//! 5. identify the fiducials by their distances, tolerating extra blobs and a missing fiducial
//!    ([`matching`]);
//! 6. the pose by Kabsch (or the paper's three-point frame), with the fiducial registration error
//!    ([`register`]).
//!
//! [`pipeline::Tracker`] runs it all; [`render`] makes synthetic frames with ground truth;
//! [`overlay`] draws what happened; [`source::VisionPoseSource`] feeds the control loop. Files
//! are the caller's business: [`codec`] works on bytes.
//!
//! **Limits.** No I/O, no camera: frames in as buffers, poses out.

pub mod blobs;
pub mod codec;
pub mod error;
pub mod geometry;
pub mod intrinsics;
pub mod matching;
pub mod overlay;
pub mod params;
pub mod pipeline;
pub mod register;
pub mod render;
pub mod source;

pub use blobs::{Blob, Frame};
pub use error::VisionError;
pub use geometry::MarkerGeometry;
pub use intrinsics::Intrinsics;
pub use params::TrackParams;
pub use pipeline::{BlobStatus, Detection, FrameResult, NotFound, Tracker};
