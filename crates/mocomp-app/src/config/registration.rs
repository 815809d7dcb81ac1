//! `[registration]`: how `mocomp register` registers the patient's head to the image, in
//! millimetres at the file: the landmarks to touch, the noise each input is weighed by (stated
//! here, never learned from the fit: see [`mocomp_nav::noise`]), the limits a result is held to,
//! and when the sweep is enough.
//!
//! ```toml
//! [registration]
//! landmarks = ["nasion", "lpa", "rpa"]
//! max_fre_mm = 4.0
//! sweep_points = 300            # the most
//! min_sweep_points = 40         # the fewest before the sweep may end early
//! sweep_until_mm = 2.0          # the sweep ends when the error bound at every target is under this
//! retouches = 2                 # a landmark that disagrees with the others is asked for again
//! [registration.noise]
//! touch_sigma_mm = 0.7          # where a touch lands on the skin, per axis along it (1 mm RMS)
//! image_landmark_sigma_mm = 0.7 # where the image's landmark lies against the same point
//! tracker_sigma_mm = 0.25       # the tracked tip, per axis
//! skin_compression_mm = 1.0     # the skin gives under the tip by up to this
//! model_sigma_mm = 0.5          # the scalp model against the skin, alike over
//! model_correlation_mm = 20.0   # this distance, and in or out as a whole by
//! model_offset_mm = 0.3
//! ```

use crate::AppError;
use mocomp_nav::{CaptureOptions, Limits, NoiseModel, Settings, SweepOptions, Target};
use serde::{Deserialize, Serialize};

use mocomp_geom::units::MM_PER_M;

/// How a touch is told apart under `noise`: a burst of tips is still when every tip is within
/// 4 σ of the tracked tip's noise of its median (1 mm at least).
pub fn capture_options(noise: &NoiseModel) -> CaptureOptions {
    CaptureOptions {
        hold_within_m: (4.0 * noise.tracker_sigma_m).max(1e-3),
        ..CaptureOptions::default()
    }
}

/// `[registration]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegistrationSection {
    /// The landmarks to touch, in order (each named in `[head.landmarks]`).
    pub landmarks: Vec<String>,
    /// The landmarks' FRE (the RMS of their errors in the final fit) at most, mm.
    pub max_fre_mm: f64,
    /// Sweep points at most (0: the landmarks alone).
    pub sweep_points: usize,
    /// Sweep points at least before the sweep may end early.
    pub min_sweep_points: usize,
    /// The sweep ends when the error bound at every target is under this, mm (0: only at
    /// `sweep_points`).
    pub sweep_until_mm: f64,
    /// How often a landmark that disagrees with the others is asked for again.
    pub retouches: usize,
    /// `[registration.noise]`: what each input is worth.
    pub noise: NoiseSection,
}

/// `[registration.noise]` (and the registration file's): the noise each input is weighed by, mm.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NoiseSection {
    /// Where a touch lands on the skin against the anatomical point, per axis along the skin.
    pub touch_sigma_mm: f64,
    /// Where the image's landmark lies against the same point, per axis along the scalp.
    pub image_landmark_sigma_mm: f64,
    /// The tracked tip's noise, per axis.
    pub tracker_sigma_mm: f64,
    /// The skin gives under the tip by up to this.
    pub skin_compression_mm: f64,
    /// The scalp model's error against the skin, along its normal.
    pub model_sigma_mm: f64,
    /// The distance over which that error is alike.
    pub model_correlation_mm: f64,
    /// Its part common to the whole head.
    pub model_offset_mm: f64,
}

impl Default for NoiseSection {
    fn default() -> Self {
        let n = NoiseModel::default();
        Self {
            touch_sigma_mm: n.touch_sigma_m * MM_PER_M,
            image_landmark_sigma_mm: n.image_landmark_sigma_m * MM_PER_M,
            tracker_sigma_mm: n.tracker_sigma_m * MM_PER_M,
            skin_compression_mm: n.skin_compression_m * MM_PER_M,
            model_sigma_mm: n.model_sigma_m * MM_PER_M,
            model_correlation_mm: n.model_correlation_m * MM_PER_M,
            model_offset_mm: n.model_offset_m * MM_PER_M,
        }
    }
}

impl NoiseSection {
    /// The noise model, m.
    pub fn model(&self) -> NoiseModel {
        let m = |mm: f64| mm / MM_PER_M;
        NoiseModel {
            touch_sigma_m: m(self.touch_sigma_mm),
            image_landmark_sigma_m: m(self.image_landmark_sigma_mm),
            tracker_sigma_m: m(self.tracker_sigma_mm),
            skin_compression_m: m(self.skin_compression_mm),
            model_sigma_m: m(self.model_sigma_mm),
            model_correlation_m: m(self.model_correlation_mm),
            model_offset_m: m(self.model_offset_mm),
        }
    }
}

impl Default for RegistrationSection {
    fn default() -> Self {
        Self {
            landmarks: vec!["nasion".into(), "lpa".into(), "rpa".into()],
            max_fre_mm: 4.0,
            sweep_points: 300,
            min_sweep_points: 40,
            sweep_until_mm: 2.0,
            retouches: 2,
            noise: NoiseSection::default(),
        }
    }
}

impl RegistrationSection {
    /// The noise model, m.
    pub fn noise(&self) -> NoiseModel {
        self.noise.model()
    }

    /// Every value in range, the key named.
    pub fn validate(&self) -> Result<(), AppError> {
        if self.landmarks.len() < 3 {
            return Err(AppError::Config(format!(
                "registration.landmarks = {:?}: a registration needs three at least",
                self.landmarks
            )));
        }
        self.noise()
            .validate()
            .map_err(|e| AppError::Config(format!("registration.noise.{}_mm: {}", e.key, e.why)))?;
        if !(self.max_fre_mm.is_finite() && self.max_fre_mm > 0.0 && self.max_fre_mm <= 50.0) {
            return Err(AppError::Config(format!(
                "registration.max_fre_mm = {}: must be in (0, 50]",
                self.max_fre_mm
            )));
        }
        if !(self.sweep_until_mm.is_finite() && (0.0..=50.0).contains(&self.sweep_until_mm)) {
            return Err(AppError::Config(format!(
                "registration.sweep_until_mm = {}: must be in [0, 50]",
                self.sweep_until_mm
            )));
        }
        if self.sweep_points > 100_000 {
            return Err(AppError::Config(format!(
                "registration.sweep_points = {}: at most 100000",
                self.sweep_points
            )));
        }
        Ok(())
    }

    /// The procedure's settings for `targets`, the error bound held to `max_error_mm`; the
    /// landmarks and the most sweep points as given.
    pub fn settings(
        &self,
        landmarks: &[String],
        sweep_points: usize,
        targets: Vec<Target>,
        max_error_mm: f64,
    ) -> Settings {
        Settings {
            landmarks: landmarks.to_vec(),
            noise: self.noise(),
            capture: capture_options(&self.noise()),
            sweep: SweepOptions::default(),
            min_points: self.min_sweep_points,
            max_points: sweep_points,
            sweep_until_m: self.sweep_until_mm / MM_PER_M,
            retouches: self.retouches,
            targets,
            limits: Limits {
                max_fre_m: self.max_fre_mm / MM_PER_M,
                max_error_m: max_error_mm / MM_PER_M,
            },
        }
    }
}
