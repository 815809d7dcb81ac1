//! Azure Kinect recordings around the vision pipeline (`mocomp track --recording`, `mocomp track
//! render --recording`): the SDK found where the user says, a recording's captures tracked one
//! by one with the recording's own calibration (rendered frames are written by
//! [`crate::camera::k4a_writer`]).

use crate::camera::frames::track_frame;
use crate::{AppError, Context};
use mocomp_k4a::{DepthMode, Playback, Sdk};
use mocomp_vision::{Frame, FrameResult, Intrinsics, Tracker};
use std::path::Path;
use std::sync::Arc;

/// The environment variable naming the SDK's directory when the configuration does not.
pub const SDK_DIR_ENV: &str = "MOCOMP_K4A_SDK_DIR";

/// The SDK from `dir`, else from `MOCOMP_K4A_SDK_DIR`, else from the system's library path.
pub fn load_sdk(dir: Option<&Path>) -> Result<Arc<Sdk>, AppError> {
    let env = std::env::var_os(SDK_DIR_ENV).map(std::path::PathBuf::from);
    let dir = dir.or(env.as_deref());
    Sdk::load(dir).what(|| "the Azure Kinect SDK".to_string())
}

/// A recording opened for tracking: it must have IR and depth.
pub fn open_recording(sdk: &Arc<Sdk>, path: &Path) -> Result<Playback, AppError> {
    let name = path.display().to_string();
    let p = Playback::open(sdk, &name).what(|| format!("--recording {name}"))?;
    p.check_trackable().what(|| format!("--recording {name}"))?;
    Ok(p)
}

/// One capture's outcome.
#[derive(Debug)]
pub struct Tracked<'a> {
    /// Its name: the capture's index, zero-padded (as a frame directory's names).
    pub name: &'a str,
    /// The device timestamp, µs.
    pub device_usec: u64,
    /// What the pipeline made of it.
    pub result: &'a FrameResult,
}

/// What a recording held.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RecordingCount {
    /// Captures tracked.
    pub tracked: usize,
    /// Captures without IR or depth (skipped: the pipeline needs both).
    pub incomplete: usize,
    /// Frames missing between captures, by their timestamps.
    pub dropped: u64,
}

/// Tracks every capture of `p` with `tracker` (made for the recording's intrinsics), writing an
/// overlay per capture into `overlay_dir` when given; `each` is told each capture's outcome. A
/// capture the SDK cannot read ends it with an error naming how far it got.
pub fn track_recording(
    p: &mut Playback,
    tracker: &mut Tracker,
    overlay_dir: Option<&Path>,
    each: &mut dyn FnMut(&Tracked<'_>) -> Result<(), AppError>,
) -> Result<RecordingCount, AppError> {
    if let Some(d) = overlay_dir {
        std::fs::create_dir_all(d).what(|| format!("--overlay {}: cannot create", d.display()))?;
    }
    let mut gaps = mocomp_k4a::clock::Gaps::new(p.info().fps);
    let mut count = RecordingCount::default();
    let mut index = 0usize;
    while let Some(c) = p.next_capture().what(|| p.path().to_string())? {
        let name = format!("{index:04}");
        index += 1;
        let (Some(ir), Some(depth)) = (c.ir, c.depth) else {
            count.incomplete += 1;
            continue;
        };
        count.dropped += gaps.dropped_before(ir.device_usec);
        let frame = Frame::new(ir.width, ir.height, &ir.data, &depth.data)
            .what(|| format!("{}: capture {name}", p.path()))?;
        let result = track_frame(&name, &frame, tracker, overlay_dir)?;
        each(&Tracked {
            name: &name,
            device_usec: ir.device_usec,
            result: &result,
        })?;
        count.tracked += 1;
    }
    Ok(count)
}

/// The depth camera's intrinsics for `mode` from a device calibration file (`calibration.json`,
/// as a recording attaches it).
pub fn intrinsics_from_calibration(
    sdk: &Sdk,
    calibration: &Path,
    mode: DepthMode,
) -> Result<Intrinsics, AppError> {
    let what = || format!("--k4a-calibration {}", calibration.display());
    let raw = std::fs::read(calibration).what(what)?;
    sdk.intrinsics_from_raw(&raw, mode).what(what)
}
