//! What a depth camera shares with the front ends, and what it tells the run: the pipeline's
//! parameters and the newest frame ([`VisionLink`]), and its news ([`CameraNote`]). A leaf: it
//! knows the vision pipeline and nothing of the loop or the session.

use crate::FrontendError;
use mocomp_vision::{Frame, FrameResult, TrackParams};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

/// The newest frame and what the pipeline made of it.
#[derive(Debug, Clone)]
pub struct Preview {
    /// Seconds since the camera started.
    pub t_s: f64,
    /// Frames taken so far.
    pub frames: u64,
    /// Frames in which the marker was found so far.
    pub found: u64,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// IR image.
    pub ir: Vec<u16>,
    /// Depth image, mm.
    pub depth: Vec<u16>,
    /// The scan area the pipeline used.
    pub scan_area: [u32; 4],
    /// The pipeline's result.
    pub result: FrameResult,
}

/// What the camera and a front end share: the pipeline's parameters (a front end may change
/// them; the camera takes them before its next frame) and the newest frame.
#[derive(Debug)]
pub struct VisionLink {
    params: Mutex<TrackParams>,
    version: AtomicU64,
    preview: Mutex<Option<Arc<Preview>>>,
}

/// The value behind `m`, whether or not a thread panicked holding it (the values kept here stay
/// whole: each is replaced at once).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl VisionLink {
    /// A link with these parameters and no frame yet.
    pub fn new(params: TrackParams) -> Arc<Self> {
        Arc::new(Self {
            params: Mutex::new(params),
            version: AtomicU64::new(0),
            preview: Mutex::new(None),
        })
    }

    /// The parameters in force.
    pub fn params(&self) -> TrackParams {
        *lock(&self.params)
    }

    /// New parameters, for the next frame; checked as the configuration file checks them.
    pub fn set_params(&self, params: TrackParams) -> Result<(), FrontendError> {
        params
            .validate("tracker.camera.params")
            .map_err(|e| FrontendError::Config(e.to_string()))?;
        *lock(&self.params) = params;
        self.version.fetch_add(1, Ordering::Release);
        Ok(())
    }

    /// Which parameters are in force: it changes with every [`Self::set_params`] (the camera
    /// takes new ones before its next frame when it does).
    pub fn params_version(&self) -> u64 {
        self.version.load(Ordering::Acquire)
    }

    /// The camera's newest frame with its result, for the front ends.
    pub fn show(&self, preview: Preview) {
        *lock(&self.preview) = Some(Arc::new(preview));
    }

    /// The newest frame with its result.
    pub fn preview(&self) -> Option<Arc<Preview>> {
        lock(&self.preview).clone()
    }

    /// The newest frame with the paper's overlays (scan area, blobs with boxes, fiducials
    /// numbered, rejected blobs crossed) as a PNG; `None` before the first frame.
    pub fn overlay_png(&self) -> Result<Option<Vec<u8>>, FrontendError> {
        let Some(p) = self.preview() else {
            return Ok(None);
        };
        let vision = |what| move |source| FrontendError::Vision { what, source };
        let frame =
            Frame::new(p.width, p.height, &p.ir, &p.depth).map_err(vision("the camera's frame"))?;
        let img = mocomp_vision::overlay::overlay(&frame, p.scan_area, &p.result);
        mocomp_vision::codec::encode_rgb_png(img.width, img.height, &img.data, "overlay")
            .map(Some)
            .map_err(vision("encoding the camera's overlay"))
    }
}

/// Why a feed ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum FeedEnd {
    /// A recording's last capture was played.
    RecordingEnded,
    /// A recording could not be read on (truncated or damaged).
    RecordingDamaged,
    /// The device stopped delivering (unplugged, or its USB link failed).
    DeviceLost,
}

impl std::fmt::Display for FeedEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::RecordingEnded => "the recording ended",
            Self::RecordingDamaged => "the recording is damaged past this point",
            Self::DeviceLost => "the camera stopped delivering frames (unplugged?)",
        })
    }
}

/// What a camera note says (sent to the run's notes, stamped on the loop's clock).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CameraNote {
    /// Frames dropped before the frame at hand.
    Dropped(u64),
    /// The feed ended.
    Ended(FeedEnd),
}

impl std::fmt::Display for CameraNote {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Dropped(n) => write!(f, "depth camera: {n} frame(s) dropped"),
            Self::Ended(e) => write!(f, "depth camera: {e}; no more head poses"),
        }
    }
}
