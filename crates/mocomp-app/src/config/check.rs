//! [`Config::check`]: every value the components do not check themselves, and theirs.

use super::*;

impl Config {
    /// Checks every value the components do not check themselves, and theirs; errors name the
    /// key.
    pub fn check(&self) -> Result<(), AppError> {
        self.calibrate.check()?;
        self.params
            .validate()
            .map_err(|e| in_section(&e, "loop."))?;
        self.predictor
            .validate()
            .map_err(|e| in_section(&e, "predictor."))?;
        self.realtime.validate().map_err(|e| in_section(&e, ""))?;
        self.tracker.check()?;
        self.registration.validate()?;
        Check::non_negative("duration_s", self.duration_s)?;
        Check::range("head.max_tre_mm", self.head.max_tre_mm, 0.0, 50.0, false)?;
        self.ros2.check()?;
        self.session.check(&self.coil)?;
        for (i, r) in self.head.radii_m.iter().enumerate() {
            Check::positive(&format!("head.radii_m[{i}]"), *r)?;
        }
        Check::positive("coil.radius_m", self.coil.radius_m)?;
        Check::positive("coil.thickness_m", self.coil.thickness_m)?;
        coil::check(&self.coil)?;
        self.servo.check()?;
        self.robot.check()?;
        Ok(())
    }
}

/// A component's own check's message, its key given the section's path.
pub(super) fn in_section(e: &dyn std::fmt::Display, section: &str) -> AppError {
    AppError::Config(format!("{section}{e}"))
}
