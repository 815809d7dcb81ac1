//! Writing Azure Kinect recordings through the SDK's own recorder (no device: user captures of
//! IR and depth), with a calibration attached as the SDK's recorder attaches a device's, so the
//! SDK's playback (and `pyk4a`, `k4aviewer`) reads them like recordings from a camera. For test
//! recordings of rendered markers, and converting frame directories.

use crate::error::K4aError;
use crate::ffi::{DeviceConfiguration, FORMAT_CUSTOM};
use crate::handles::{RecordHandle, Sdk};
use crate::modes::{DepthMode, fps_raw};
use std::sync::Arc;

/// A recording being written.
pub struct Recorder {
    h: Option<RecordHandle>,
    path: String,
    size: (u32, u32),
    captures: u64,
}

impl std::fmt::Debug for Recorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("path", &self.path)
            .field("captures", &self.captures)
            .finish_non_exhaustive()
    }
}

impl Recorder {
    /// Creates `path` for IR and depth in `mode` at `fps`, with `calibration_json` (the SDK's raw
    /// calibration, as `k4a_device_get_raw_calibration` gives and a recording's
    /// `calibration.json` attachment holds) attached.
    pub fn create(
        sdk: &Arc<Sdk>,
        path: &str,
        mode: DepthMode,
        fps: u32,
        calibration_json: &[u8],
    ) -> Result<Self, K4aError> {
        let camera_fps = fps_raw(fps).ok_or_else(|| {
            K4aError::Mode(format!("{fps} frames a second: the camera has 5, 15 or 30"))
        })?;
        if fps > mode.max_fps() {
            return Err(K4aError::Mode(format!(
                "{mode:?} runs at most {} frames a second",
                mode.max_fps()
            )));
        }
        let config = DeviceConfiguration {
            color_format: FORMAT_CUSTOM,
            depth_mode: mode.raw(),
            camera_fps,
            ..DeviceConfiguration::default()
        };
        let mut h = RecordHandle::create(sdk, path, config)?;
        // Where the SDK's playback looks for the calibration: the tag names the attachment.
        h.add_tag("K4A_CALIBRATION_FILE", "calibration.json")?;
        h.add_attachment("calibration.json", calibration_json)?;
        h.write_header()?;
        Ok(Self {
            h: Some(h),
            path: path.to_string(),
            size: mode.size(),
            captures: 0,
        })
    }

    /// Writes one capture (IR and depth, the mode's size, row-major) at `device_usec`.
    pub fn write(&mut self, ir: &[u16], depth: &[u16], device_usec: u64) -> Result<(), K4aError> {
        let h = self
            .h
            .as_mut()
            .ok_or_else(|| K4aError::BadArgument("the recording is closed".into()))?;
        h.write(self.size.0, self.size.1, ir, depth, device_usec)?;
        self.captures += 1;
        Ok(())
    }

    /// Flushes and closes the file; returns the captures written.
    pub fn finish(mut self) -> Result<u64, K4aError> {
        if let Some(mut h) = self.h.take() {
            h.flush()?;
        }
        Ok(self.captures)
    }
}
