//! A live Azure Kinect (or an Orbbec Femto through Orbbec's k4a-compatible library): opened by
//! serial number, its factory calibration for the chosen depth mode, its captures.

use crate::error::K4aError;
use crate::ffi::DeviceConfiguration;
use crate::handles::{Capture16, DeviceHandle, Sdk};
use crate::modes::{DepthMode, fps_raw};
use mocomp_vision::Intrinsics;
use std::sync::Arc;

/// An open device.
pub struct Device {
    h: DeviceHandle,
    serial: String,
}

impl std::fmt::Debug for Device {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Device")
            .field("serial", &self.serial)
            .finish_non_exhaustive()
    }
}

impl Device {
    /// Opens the device with `serial`, or the only one connected.
    pub fn open(sdk: &Arc<Sdk>, serial: Option<&str>) -> Result<Self, K4aError> {
        let n = sdk.installed_devices();
        if n == 0 {
            return Err(K4aError::NoDevice(
                "no Azure Kinect is connected (the SDK finds none on USB)".into(),
            ));
        }
        let mut seen = Vec::new();
        for i in 0..n {
            // A device another program holds cannot be opened: named below with the others.
            let Ok(h) = DeviceHandle::open(sdk, i) else {
                seen.push(format!("#{i} (in use)"));
                continue;
            };
            let s = h.serial()?;
            match serial {
                Some(want) if want != s => seen.push(s),
                _ if serial.is_none() && n > 1 => {
                    return Err(K4aError::NoDevice(format!(
                        "{n} Azure Kinects are connected: say which by tracker.k4a.serial"
                    )));
                }
                _ => return Ok(Self { h, serial: s }),
            }
        }
        Err(K4aError::NoDevice(format!(
            "no Azure Kinect with serial {} (connected: {})",
            serial.unwrap_or("?"),
            seen.join(", ")
        )))
    }

    /// Its serial number.
    pub fn serial(&self) -> &str {
        &self.serial
    }

    /// The depth camera's factory intrinsics in `mode`.
    pub fn intrinsics(&self, mode: DepthMode) -> Result<Intrinsics, K4aError> {
        let c = self.h.calibration(mode.raw())?;
        crate::calibration::intrinsics(&c.depth_camera)
    }

    /// Starts IR and depth in `mode` at `fps` (colour off).
    pub fn start(&mut self, mode: DepthMode, fps: u32) -> Result<(), K4aError> {
        if !mode.has_depth() {
            return Err(K4aError::Mode(
                "passive IR has no depth, which the pipeline needs".into(),
            ));
        }
        let camera_fps = fps_raw(fps)
            .filter(|_| fps <= mode.max_fps())
            .ok_or_else(|| {
                K4aError::Mode(format!(
                    "{fps} frames a second in {mode:?}: the camera has 5, 15 or 30 (at most {})",
                    mode.max_fps()
                ))
            })?;
        self.h.start(&DeviceConfiguration {
            depth_mode: mode.raw(),
            camera_fps,
            ..DeviceConfiguration::default()
        })
    }

    /// The next capture within `timeout_ms` (`None`: none in time); [`K4aError::DeviceLost`]
    /// when the device failed.
    pub fn next_capture(&mut self, timeout_ms: i32) -> Result<Option<Capture16>, K4aError> {
        self.h.next(timeout_ms)
    }
}
