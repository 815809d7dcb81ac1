//! The expected measurement noise of robot and tracker, which weights the refined solver's
//! residuals and sets the tolerances of the consistency checks.

use crate::error::CalibError;
use mocomp_geom::units::{deg_to_rad, mm_to_m};

/// Per-axis standard deviations of the measurement noise (metres, radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Tracker position noise, per axis, metres.
    pub tracker_translation_m: f64,
    /// Tracker orientation noise, per axis, radians.
    pub tracker_rotation_rad: f64,
    /// Robot (flange pose) position noise, per axis, metres.
    pub robot_translation_m: f64,
    /// Robot orientation noise, per axis, radians.
    pub robot_rotation_rad: f64,
}

impl Default for NoiseModel {
    /// An optical tracker at 0.1 mm / 0.1° and a UR arm at 0.03 mm / 0.01°.
    fn default() -> Self {
        Self::from_mm_deg(0.1, 0.1, 0.03, 0.01)
    }
}

impl NoiseModel {
    /// From millimetres and degrees (tracker position, tracker rotation, robot position, robot
    /// rotation).
    pub fn from_mm_deg(tracker_mm: f64, tracker_deg: f64, robot_mm: f64, robot_deg: f64) -> Self {
        Self {
            tracker_translation_m: mm_to_m(tracker_mm),
            tracker_rotation_rad: deg_to_rad(tracker_deg),
            robot_translation_m: mm_to_m(robot_mm),
            robot_rotation_rad: deg_to_rad(robot_deg),
        }
    }

    /// Checks every value is finite and positive (zero noise would give infinite weights).
    pub fn validate(&self) -> Result<(), CalibError> {
        for (name, v) in [
            ("tracker translation noise", self.tracker_translation_m),
            ("tracker rotation noise", self.tracker_rotation_rad),
            ("robot translation noise", self.robot_translation_m),
            ("robot rotation noise", self.robot_rotation_rad),
        ] {
            if !v.is_finite() || v <= 0.0 {
                return Err(CalibError::InvalidOption(format!(
                    "{name} must be a positive number, got {v}"
                )));
            }
        }
        Ok(())
    }

    /// Per-axis standard deviation of the rotation residual of one pair, radians.
    pub fn residual_rotation_sigma(&self) -> f64 {
        self.tracker_rotation_rad.hypot(self.robot_rotation_rad)
    }

    /// Per-axis standard deviation of the translation residual of one pair, metres, for a marker
    /// `lever_m` from the flange origin (the robot's rotation noise moves the marker by
    /// `ω × lever`, whose per-axis variance averages `⅔·σ²·|lever|²`).
    pub fn residual_translation_sigma(&self, lever_m: f64) -> f64 {
        let rot = self.robot_rotation_rad * lever_m;
        (self.tracker_translation_m.powi(2)
            + self.robot_translation_m.powi(2)
            + (2.0 / 3.0) * rot * rot)
            .sqrt()
    }
}
