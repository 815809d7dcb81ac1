//! Rendered frames written as an Azure Kinect recording (`mocomp track render --recording`),
//! through the SDK's recorder, with a device's calibration attached.

use crate::{AppError, Context};
use mocomp_k4a::{DepthMode, Recorder, Sdk};
use std::path::Path;
use std::sync::Arc;

/// A recording being written from rendered frames, at `fps`, starting at `start_usec`.
#[derive(Debug)]
pub struct RecordingSink {
    recorder: Recorder,
    period_usec: u64,
    start_usec: u64,
    frames: u64,
}

impl RecordingSink {
    /// Creates `path` for `mode` at `fps` with `calibration` (a device's `calibration.json`)
    /// attached.
    pub fn create(
        sdk: &Arc<Sdk>,
        path: &Path,
        mode: DepthMode,
        fps: u32,
        calibration: &Path,
    ) -> Result<Self, AppError> {
        let raw = std::fs::read(calibration)
            .what(|| format!("--k4a-calibration {}", calibration.display()))?;
        // As `--out`: the directory is made when it is not there.
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).what(|| {
                format!(
                    "--recording {}: cannot create its directory",
                    path.display()
                )
            })?;
        }
        let recorder = Recorder::create(sdk, &path.display().to_string(), mode, fps, &raw)
            .what(|| format!("--recording {}", path.display()))?;
        Ok(Self {
            recorder,
            period_usec: 1_000_000 / u64::from(fps.max(1)),
            // As a camera's clock: not zero at the first frame.
            start_usec: 1_000_000,
            frames: 0,
        })
    }

    /// Writes the next frame, one period after the last.
    pub fn write(&mut self, ir: &[u16], depth: &[u16]) -> Result<(), AppError> {
        let t = self.start_usec + self.frames * self.period_usec;
        self.recorder
            .write(ir, depth, t)
            .what(|| format!("recording frame {}", self.frames))?;
        self.frames += 1;
        Ok(())
    }

    /// Closes the file.
    pub fn finish(self) -> Result<u64, AppError> {
        self.recorder.finish().what(|| "closing the recording")
    }
}
