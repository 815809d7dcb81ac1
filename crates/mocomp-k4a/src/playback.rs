//! An Azure Kinect recording (`.mkv`, as `k4arecorder` or [`crate::Recorder`] writes it) played
//! through the SDK: its configuration, the depth camera's factory calibration as intrinsics,
//! and its captures' IR and depth images with their device timestamps.

use crate::error::K4aError;
use crate::handles::{Capture16, Next, PlaybackHandle, Sdk};
use crate::modes::{DepthMode, fps_from_raw};
use mocomp_vision::Intrinsics;
use std::sync::Arc;

/// What a recording says about itself.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordingInfo {
    /// The depth mode (`None`: depth and IR were off).
    pub depth_mode: Option<DepthMode>,
    /// Frames per second.
    pub fps: u32,
    /// It has an IR track.
    pub ir_track: bool,
    /// It has a depth track.
    pub depth_track: bool,
    /// The first capture's device timestamp, µs.
    pub start_offset_usec: u32,
    /// Its length, µs.
    pub length_usec: u64,
    /// The device's serial number, when recorded from one.
    pub serial: Option<String>,
}

/// An open recording.
pub struct Playback {
    h: PlaybackHandle,
    path: String,
    info: RecordingInfo,
    calibration: Result<Intrinsics, String>,
    captures: u64,
    last_usec: u64,
}

impl std::fmt::Debug for Playback {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Playback")
            .field("path", &self.path)
            .field("info", &self.info)
            .finish_non_exhaustive()
    }
}

impl Playback {
    /// Opens `path`. An error names the file (missing, not a recording, cut short before its
    /// track information).
    pub fn open(sdk: &Arc<Sdk>, path: &str) -> Result<Self, K4aError> {
        if let Err(e) = std::fs::metadata(path) {
            return Err(K4aError::Recording {
                path: path.to_string(),
                detail: e.to_string(),
            });
        }
        let h = PlaybackHandle::open(sdk, path)?;
        let c = h.configuration()?;
        let depth_mode = DepthMode::from_raw(c.depth_mode);
        let info = RecordingInfo {
            depth_mode,
            fps: fps_from_raw(c.camera_fps).unwrap_or(0),
            ir_track: c.ir_track_enabled,
            depth_track: c.depth_track_enabled,
            start_offset_usec: c.start_timestamp_offset_usec,
            length_usec: h.length_usec(),
            serial: h.tag("K4A_DEVICE_SERIAL_NUMBER"),
        };
        // A recording without a calibration still plays; asking for its intrinsics says why not.
        let calibration = h
            .calibration()
            .and_then(|c| crate::calibration::intrinsics(&c.depth_camera))
            .map_err(|e| e.to_string());
        Ok(Self {
            h,
            path: path.to_string(),
            info,
            calibration,
            captures: 0,
            last_usec: 0,
        })
    }

    /// The file.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// Its configuration.
    pub fn info(&self) -> &RecordingInfo {
        &self.info
    }

    /// The depth camera's intrinsics (IR and depth share that camera), from the calibration the
    /// recording carries.
    pub fn intrinsics(&self) -> Result<Intrinsics, K4aError> {
        self.calibration.clone().map_err(|e| K4aError::Recording {
            path: self.path.clone(),
            detail: format!("no usable calibration: {e}"),
        })
    }

    /// Checks it can feed the pipeline: IR and depth tracks.
    pub fn check_trackable(&self) -> Result<(), K4aError> {
        if !(self.info.ir_track && self.info.depth_track) {
            return Err(K4aError::Recording {
                path: self.path.clone(),
                detail: format!(
                    "the pipeline needs IR and depth; it has {}{}",
                    if self.info.ir_track { "IR" } else { "no IR" },
                    if self.info.depth_track {
                        " and depth"
                    } else {
                        " and no depth"
                    }
                ),
            });
        }
        Ok(())
    }

    /// The next capture (`None` at the end). A capture the SDK cannot read (a truncated or
    /// damaged file) is an error naming how far it got.
    pub fn next_capture(&mut self) -> Result<Option<Capture16>, K4aError> {
        match self.h.next() {
            Ok(Next::Capture(c)) => {
                self.captures += 1;
                if let Some(i) = c.ir.as_ref().or(c.depth.as_ref()) {
                    self.last_usec = i.device_usec;
                }
                Ok(Some(c))
            }
            Ok(Next::End) => Ok(None),
            Err(K4aError::Call { .. }) => Err(K4aError::Damaged {
                path: self.path.clone(),
                captures: self.captures,
                after_usec: self.last_usec,
            }),
            Err(e) => Err(e),
        }
    }
}
