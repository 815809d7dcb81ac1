//! A tracked pointer (stylus) streamed over OpenIGTLink: its poses collected while it pivots on a
//! divot, calibrated ([`mocomp_nav::pivot`]) and kept in a file (millimetres at the file, metres
//! in here), from which registration reads the tip.
//!
//! ```toml
//! [pointer]
//! device = "StylusToTracker"
//! tip_in_marker_mm = [0.12, -0.31, 160.05]
//! rms_mm = 0.41
//! ...
//! ```

use crate::listen::{ListenOptions, listen};
use crate::{AppError, Context};
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_igtl::message::F32_RIGID_TOLERANCE;
use mocomp_nav::PivotCalibration;
use serde::{Deserialize, Serialize};
use std::ops::ControlFlow;
use std::path::Path;
use std::time::Duration;

/// The pointer file's one table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointerFile {
    /// The pointer.
    pub pointer: Pointer,
}

/// A calibrated pointer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pointer {
    /// Its TRANSFORM device or TDATA tool name.
    pub device: String,
    /// The tip in its marker's frame, mm.
    pub tip_in_marker_mm: [f64; 3],
    /// The divot in the tracker's frame during calibration, mm.
    pub pivot_in_tracker_mm: [f64; 3],
    /// The kept tips' RMS distance from the divot, mm.
    pub rms_mm: f64,
    /// Their largest, mm.
    pub max_mm: f64,
    /// Samples kept.
    pub kept: usize,
    /// Samples dropped as outliers.
    pub rejected: usize,
    /// Poses the tracker marked invalid, not used.
    pub invalid: usize,
    /// How far the pointer turned about two independent axes, degrees.
    pub spread_deg: f64,
    /// When (an HTTP date, UTC).
    pub calibrated_at: String,
}

impl Pointer {
    /// The tip in the marker's frame, m.
    pub fn tip(&self) -> Vector3<f64> {
        Vector3::from(self.tip_in_marker_mm) / 1000.0
    }

    fn from_calibration(device: &str, c: &PivotCalibration, invalid: usize) -> Self {
        let mm = |v: Vector3<f64>| -> [f64; 3] { (v * 1000.0).into() };
        Self {
            device: device.to_string(),
            tip_in_marker_mm: mm(c.tip_in_marker),
            pivot_in_tracker_mm: mm(c.pivot_in_tracker.coords),
            rms_mm: c.rms_m * 1000.0,
            max_mm: c.max_m * 1000.0,
            kept: c.kept,
            rejected: c.rejected,
            invalid,
            spread_deg: c.spread_rad.to_degrees(),
            calibrated_at: crate::navigation::targets::now(),
        }
    }
}

/// What a calibration found, as a person reads it.
impl std::fmt::Display for Pointer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [x, y, z] = self.tip_in_marker_mm;
        write!(
            f,
            "{}: tip at ({x:.2}, {y:.2}, {z:.2}) mm in the marker's frame; the tips agree to \
             {:.2} mm RMS, {:.2} mm at most ({} of {} poses kept, {} invalid left out, turned \
             {:.0}°)",
            self.device,
            self.rms_mm,
            self.max_mm,
            self.kept,
            self.kept + self.rejected,
            self.invalid,
            self.spread_deg,
        )
    }
}

/// `count` poses of `device` from the OpenIGTLink server at `addr` (`tracker_from_marker`, m),
/// and how many more arrived marked invalid (left out); `each` is told how many are in.
pub fn collect(
    addr: &str,
    device: &str,
    count: usize,
    timeout: Duration,
    each: &mut dyn FnMut(usize),
) -> Result<(Vec<Isometry3<f64>>, usize), AppError> {
    let mut poses = Vec::with_capacity(count);
    let mut invalid = 0usize;
    let o = ListenOptions {
        addr: addr.to_string(),
        device: device.to_string(),
        count: None,
        timeout,
        stt_tdata: false,
    };
    listen(&o, &mut |h| {
        match h
            .valid
            .then(|| iso_from_matrix_mm(&h.matrix_mm, F32_RIGID_TOLERANCE).ok())
            .flatten()
        {
            Some(p) => {
                poses.push(p);
                each(poses.len());
            }
            None => invalid += 1,
        }
        Ok(if poses.len() >= count {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        })
    })?;
    Ok((poses, invalid))
}

/// Calibrates the pointer `device` from its pivoting `poses`.
pub fn calibrate(
    device: &str,
    poses: &[Isometry3<f64>],
    invalid: usize,
) -> Result<Pointer, AppError> {
    mocomp_nav::calibrate_pivot(poses)
        .map(|c| Pointer::from_calibration(device, &c, invalid))
        .map_err(|e| AppError::Refused(format!("pivot calibration of {device}: {e}")))
}

/// Writes the pointer file.
pub fn save(path: &Path, pointer: &Pointer) -> Result<(), AppError> {
    let text = toml::to_string(&PointerFile {
        pointer: pointer.clone(),
    })
    .map_err(|e| AppError::failed("writing the pointer file", e))?;
    crate::files::whole::write_whole(path, text.as_bytes(), "the pointer file")
}

/// Reads a pointer file.
pub fn load(path: &Path) -> Result<Pointer, AppError> {
    let text = std::fs::read_to_string(path)
        .what(|| format!("reading the pointer file {}", path.display()))?;
    let file: PointerFile =
        toml::from_str(&text).map_err(|e| AppError::Config(format!("{}: {e}", path.display())))?;
    let p = file.pointer;
    if !p.tip_in_marker_mm.iter().all(|v| v.is_finite()) {
        return Err(AppError::Config(format!(
            "{}: pointer.tip_in_marker_mm is not finite",
            path.display()
        )));
    }
    Ok(p)
}
