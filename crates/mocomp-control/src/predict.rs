//! Head pose prediction: a constant-velocity Kalman filter on SE(3) (position and orientation
//! each with their velocity), which also smooths tracker noise, and extrapolates the pose to the
//! time a command will take effect.
//!
//! Position: three independent 2-state filters (position, velocity) sharing one covariance
//! (isotropic noise). Orientation: an error-state filter: the innovation is the rotation vector
//! `log(q_measured · q_estimate⁻¹)` (world frame), filtered with the same 2-state model per axis
//! for (angle error, angular velocity). Process noise: white acceleration of spectral density
//! `accel_noise` (m²/s³, rad²/s³). No allocation.

use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Filter settings (section `[predictor]` of `mocomp run`'s configuration).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PredictorConfig {
    /// Tracker position noise, 1σ per axis, m.
    pub position_noise_m: f64,
    /// Tracker rotation noise, 1σ per axis, rad.
    pub rotation_noise_rad: f64,
    /// White-acceleration spectral density for position, m²/s³.
    pub accel_noise: f64,
    /// The same for rotation, rad²/s³.
    pub angular_accel_noise: f64,
    /// Longest extrapolation, s (longer horizons are clamped: the error grows with its square).
    pub max_horizon_s: f64,
    /// How strongly velocities within their own uncertainty are shrunk before extrapolating
    /// (0: never; 4: a velocity of 2σ is halved; 0.5: a velocity of 1σ keeps 2/3).
    pub velocity_shrink: f64,
}

impl Default for PredictorConfig {
    fn default() -> Self {
        Self {
            position_noise_m: 1e-4,
            rotation_noise_rad: 1e-3,
            accel_noise: 3e-4,
            angular_accel_noise: 0.03,
            max_horizon_s: 0.15,
            velocity_shrink: 0.5,
        }
    }
}

impl PredictorConfig {
    /// Checks every value's range; the error names the first key out of range.
    pub fn validate(&self) -> Result<(), crate::ParamError> {
        for (key, value, positive) in [
            ("position_noise_m", self.position_noise_m, true),
            ("rotation_noise_rad", self.rotation_noise_rad, true),
            ("accel_noise", self.accel_noise, true),
            ("angular_accel_noise", self.angular_accel_noise, true),
            ("max_horizon_s", self.max_horizon_s, false),
            ("velocity_shrink", self.velocity_shrink, false),
        ] {
            let ok = value.is_finite() && if positive { value > 0.0 } else { value >= 0.0 };
            if !ok {
                return Err(crate::ParamError {
                    key,
                    value,
                    problem: if positive {
                        "must be finite and > 0"
                    } else {
                        "must be finite and ≥ 0"
                    },
                });
            }
        }
        Ok(())
    }
}

/// One 2-state (value, rate) covariance, shared by three axes.
#[derive(Debug, Clone, Copy)]
struct Cov2 {
    p00: f64,
    p01: f64,
    p11: f64,
}

impl Cov2 {
    fn initial(r: f64) -> Self {
        Self {
            p00: r,
            p01: 0.0,
            p11: 1.0,
        }
    }

    fn propagate(&mut self, dt: f64, q: f64) {
        let (p00, p01, p11) = (self.p00, self.p01, self.p11);
        self.p00 = p00 + 2.0 * dt * p01 + dt * dt * p11 + q * dt * dt * dt / 3.0;
        self.p01 = p01 + dt * p11 + q * dt * dt / 2.0;
        self.p11 = p11 + q * dt;
    }

    /// Kalman gains for a value measurement with variance `r`; updates the covariance.
    fn update(&mut self, r: f64) -> (f64, f64) {
        let s = self.p00 + r;
        let k0 = self.p00 / s;
        let k1 = self.p01 / s;
        let (p00, p01, p11) = (self.p00, self.p01, self.p11);
        self.p00 = (1.0 - k0) * p00;
        self.p01 = (1.0 - k0) * p01;
        self.p11 = p11 - k1 * p01;
        (k0, k1)
    }
}

/// The filter.
#[derive(Debug, Clone)]
pub struct PosePredictor {
    config: PredictorConfig,
    t: f64,
    p: Vector3<f64>,
    v: Vector3<f64>,
    q: UnitQuaternion<f64>,
    w: Vector3<f64>,
    cp: Cov2,
    cr: Cov2,
    initialised: bool,
}

impl PosePredictor {
    /// An empty filter.
    pub fn new(config: PredictorConfig) -> Self {
        Self {
            config,
            t: 0.0,
            p: Vector3::zeros(),
            v: Vector3::zeros(),
            q: UnitQuaternion::identity(),
            w: Vector3::zeros(),
            cp: Cov2::initial(1.0),
            cr: Cov2::initial(1.0),
            initialised: false,
        }
    }

    /// Forgets everything (after a dropout longer than the filter should bridge).
    pub fn reset(&mut self) {
        *self = Self::new(self.config);
    }

    /// Whether a measurement has been taken.
    pub fn is_initialised(&self) -> bool {
        self.initialised
    }

    /// Time of the newest measurement, s.
    pub fn time_s(&self) -> f64 {
        self.t
    }

    /// Estimated linear velocity (m/s) and angular velocity (rad/s, world frame).
    pub fn velocity(&self) -> (Vector3<f64>, Vector3<f64>) {
        (self.v, self.w)
    }

    /// Takes a measurement of `tracker_from_marker` acquired at `t` (s). Measurements older than
    /// the newest one are ignored.
    pub fn update(&mut self, t: f64, pose: &Isometry3<f64>) {
        let pm = pose.translation.vector;
        let qm = pose.rotation;
        let c = self.config;
        if !self.initialised {
            self.p = pm;
            self.q = qm;
            self.v = Vector3::zeros();
            self.w = Vector3::zeros();
            self.cp = Cov2 {
                p00: c.position_noise_m.powi(2),
                p01: 0.0,
                p11: 0.01,
            };
            self.cr = Cov2 {
                p00: c.rotation_noise_rad.powi(2),
                p01: 0.0,
                p11: 0.01,
            };
            self.t = t;
            self.initialised = true;
            return;
        }
        let dt = t - self.t;
        if dt <= 0.0 {
            return;
        }
        // Predict to t.
        self.p += self.v * dt;
        self.q = UnitQuaternion::from_scaled_axis(self.w * dt) * self.q;
        self.cp.propagate(dt, c.accel_noise);
        self.cr.propagate(dt, c.angular_accel_noise);
        // Update.
        let (k0, k1) = self.cp.update(c.position_noise_m.powi(2));
        let y = pm - self.p;
        self.p += y * k0;
        self.v += y * k1;
        let (k0, k1) = self.cr.update(c.rotation_noise_rad.powi(2));
        let r = (qm * self.q.inverse()).scaled_axis();
        self.q = UnitQuaternion::from_scaled_axis(r * k0) * self.q;
        self.w += r * k1;
        self.t = t;
    }

    /// The pose extrapolated to time `t` (clamped to `max_horizon_s` past the newest
    /// measurement). `None` before the first measurement.
    pub fn predict(&self, t: f64) -> Option<Isometry3<f64>> {
        if !self.initialised {
            return None;
        }
        let h = (t - self.t).clamp(0.0, self.config.max_horizon_s);
        // Shrink each velocity towards zero by how much of it the filter's own uncertainty
        // explains (a Wiener-type gain): a still head's noise-driven velocity is not
        // extrapolated, a moving head's is, in full.
        let shrink = |v: &Vector3<f64>, var: f64| {
            let s2 = v.norm_squared();
            let noise = self.config.velocity_shrink * 3.0 * var;
            if s2 > 0.0 { s2 / (s2 + noise) } else { 0.0 }
        };
        let v = self.v * shrink(&self.v, self.cp.p11);
        let w = self.w * shrink(&self.w, self.cr.p11);
        Some(Isometry3::from_parts(
            Translation3::from(self.p + v * h),
            UnitQuaternion::from_scaled_axis(w * h) * self.q,
        ))
    }

    /// The filtered pose at the newest measurement's time.
    pub fn estimate(&self) -> Option<Isometry3<f64>> {
        self.predict(self.t)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn a_bad_noise_value_is_named() {
        assert!(PredictorConfig::default().validate().is_ok());
        let bad = PredictorConfig {
            angular_accel_noise: -1.0,
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "angular_accel_noise");
        let bad = PredictorConfig {
            max_horizon_s: f64::NAN,
            ..Default::default()
        };
        assert_eq!(bad.validate().unwrap_err().key, "max_horizon_s");
    }
    use mocomp_geom::{rotation_error, translation_error};

    fn pose_at(t: f64) -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(0.05 * t, -0.02 * t, 0.8),
            Vector3::new(0.0, 0.3 * t, 0.1 * t),
        )
    }

    #[test]
    fn constant_velocity_motion_is_predicted_exactly_without_noise() {
        let exact = PredictorConfig {
            velocity_shrink: 0.0,
            ..PredictorConfig::default()
        };
        let mut f = PosePredictor::new(exact);
        for k in 0..120 {
            let t = k as f64 / 60.0;
            f.update(t, &pose_at(t));
        }
        let t_last = 119.0 / 60.0;
        let p = f.predict(t_last + 0.05).unwrap();
        let truth = pose_at(t_last + 0.05);
        assert!(
            translation_error(&p, &truth) < 1e-5,
            "{}",
            translation_error(&p, &truth)
        );
        assert!(rotation_error(&p, &truth) < 1e-4);
        // Without prediction the pose would be 2.7 mm and 0.016 rad off.
        assert!(translation_error(&f.estimate().unwrap(), &truth) > 2e-3);
        // The default shrinkage keeps most of a moving head's prediction (54 mm/s here: 0.8 mm
        // left of the 2.7 mm lag).
        let mut g = PosePredictor::new(PredictorConfig::default());
        for k in 0..120 {
            let t = k as f64 / 60.0;
            g.update(t, &pose_at(t));
        }
        let p = g.predict(t_last + 0.05).unwrap();
        assert!(
            translation_error(&p, &truth) < 1.0e-3,
            "{}",
            translation_error(&p, &truth)
        );
    }

    #[test]
    fn a_still_head_noise_is_not_extrapolated() {
        // Seeded noise 0.1 mm on a still pose: the 60 ms prediction stays within the noise.
        let mut f = PosePredictor::new(PredictorConfig::default());
        let mut x = 0x1234_5678_u64;
        let mut noise = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x as f64 / u64::MAX as f64 - 0.5) * 3.46e-4 // uniform, σ = 0.1 mm
        };
        let truth = pose_at(0.0);
        let mut worst: f64 = 0.0;
        for k in 0..600 {
            let t = k as f64 / 60.0;
            let mut m = truth;
            m.translation.vector += Vector3::new(noise(), noise(), noise());
            f.update(t, &m);
            if k > 60 {
                worst = worst.max(translation_error(&f.predict(t + 0.06).unwrap(), &truth));
            }
        }
        assert!(worst < 0.6e-3, "{worst}");
    }

    #[test]
    fn horizon_is_clamped_and_stale_measurements_ignored() {
        let mut f = PosePredictor::new(PredictorConfig::default());
        assert!(f.predict(1.0).is_none());
        for k in 0..60 {
            let t = k as f64 / 60.0;
            f.update(t, &pose_at(t));
        }
        let t_last = 59.0 / 60.0;
        let far = f.predict(t_last + 10.0).unwrap();
        let clamp = f.predict(t_last + 0.15).unwrap();
        assert_eq!(far, clamp);
        let before = f.estimate().unwrap();
        f.update(0.5, &Isometry3::identity());
        assert_eq!(f.estimate().unwrap(), before);
    }
}
