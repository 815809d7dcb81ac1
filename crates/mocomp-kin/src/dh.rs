//! General standard-DH chains (for calibrated robots and for every link frame) and the DH
//! calibration file format.

use crate::error::KinError;
use crate::model::{Model, UrGeometry};
use mocomp_geom::nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
use serde::Deserialize;
use std::f64::consts::FRAC_PI_2;

/// Standard DH parameters of a six-joint chain: link `i` is
/// `Rz(q_i + theta_i) · Tz(d_i) · Tx(a_i) · Rx(alpha_i)` (metres, radians).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhParams {
    /// Link lengths `a_i`, metres.
    pub a: [f64; 6],
    /// Link offsets `d_i`, metres.
    pub d: [f64; 6],
    /// Link twists `alpha_i`, radians.
    pub alpha: [f64; 6],
    /// Joint zero offsets `theta_i`, radians (added to the joint reading).
    pub theta: [f64; 6],
}

impl DhParams {
    /// The nominal DH parameters of a UR geometry.
    pub fn nominal(g: &UrGeometry) -> Self {
        Self {
            a: [0.0, g.a2, g.a3, 0.0, 0.0, 0.0],
            d: [g.d1, 0.0, 0.0, g.d4, g.d5, g.d6],
            alpha: [FRAC_PI_2, 0.0, 0.0, FRAC_PI_2, -FRAC_PI_2, 0.0],
            theta: [0.0; 6],
        }
    }

    /// These parameters plus per-parameter deltas (UR's `calibration.conf` style).
    pub fn plus(&self, delta: &DhParams) -> Self {
        let add = |x: &[f64; 6], y: &[f64; 6]| std::array::from_fn(|i| x[i] + y[i]);
        Self {
            a: add(&self.a, &delta.a),
            d: add(&self.d, &delta.d),
            alpha: add(&self.alpha, &delta.alpha),
            theta: add(&self.theta, &delta.theta),
        }
    }

    /// The transform `link_{i-1}_from_link_i` of joint `i` (0-based) at joint value `q`.
    #[inline]
    pub fn link(&self, i: usize, q: f64) -> Isometry3<f64> {
        let (st, ct) = (q + self.theta[i]).sin_cos();
        let (sa, ca) = self.alpha[i].sin_cos();
        let r = Matrix3::new(ct, -st * ca, st * sa, st, ct * ca, -ct * sa, 0.0, sa, ca);
        Isometry3::from_parts(
            Translation3::new(self.a[i] * ct, self.a[i] * st, self.d[i]),
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
        )
    }

    /// Every link frame: `[base, base_from_link1, …, base_from_link6]` (`[6]` is the flange).
    pub fn frames(&self, q: &[f64; 6]) -> [Isometry3<f64>; 7] {
        let mut out = [Isometry3::identity(); 7];
        for i in 0..6 {
            out[i + 1] = out[i] * self.link(i, q[i]);
        }
        out
    }

    /// `base_from_flange` by chaining the six links.
    pub fn flange(&self, q: &[f64; 6]) -> Isometry3<f64> {
        let mut t = Isometry3::identity();
        for (i, qi) in q.iter().enumerate() {
            t *= self.link(i, *qi);
        }
        t
    }

    fn check_finite(&self) -> Result<(), KinError> {
        for (name, arr) in [
            ("a", &self.a),
            ("d", &self.d),
            ("alpha", &self.alpha),
            ("theta", &self.theta),
        ] {
            if let Some(i) = arr.iter().position(|v| !v.is_finite()) {
                return Err(KinError::Calibration {
                    message: format!("{name}[{i}] is not a finite number ({})", arr[i]),
                });
            }
        }
        Ok(())
    }
}

/// A robot's own calibrated kinematics: the nominal model it is a copy of, and its exact DH values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DhCalibration {
    /// The nominal model (for the closed-form IK start, limits and speeds).
    pub model: Model,
    /// The calibrated DH parameters.
    pub dh: DhParams,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DhArrays {
    a: [f64; 6],
    d: [f64; 6],
    alpha: [f64; 6],
    theta: [f64; 6],
}

impl From<DhArrays> for DhParams {
    fn from(v: DhArrays) -> Self {
        Self {
            a: v.a,
            d: v.d,
            alpha: v.alpha,
            theta: v.theta,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CalibrationFile {
    model: String,
    dh: Option<DhArrays>,
    delta: Option<DhArrays>,
}

/// Largest flange displacement (metres) a calibration may cause against the nominal model before
/// it is rejected as a wrong model or a broken file (factory calibrations move the flange by
/// millimetres, at most a few centimetres).
pub const MAX_CALIBRATION_OFFSET_M: f64 = 0.05;

impl DhCalibration {
    /// Parses a calibration file (TOML; metres, radians):
    ///
    /// ```toml
    /// model = "ur10e"
    /// # either the absolute values the controller reports (primary interface, "Kinematics info"):
    /// [dh]
    /// a     = [0.0, -0.6127, -0.57155, 0.0, 0.0, 0.0]
    /// d     = [0.1807, 0.0, 0.0, 0.17415, 0.11985, 0.11655]
    /// alpha = [1.570796327, 0.0, 0.0, 1.570796327, -1.570796327, 0.0]
    /// theta = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    /// # or, instead of [dh], the deltas on the nominal values (calibration.conf's [mounting]):
    /// # [delta]
    /// # a = [...]  d = [...]  alpha = [...]  theta = [...]
    /// ```
    ///
    /// Unknown keys are rejected; parse errors carry the line and column. A calibration that moves
    /// the flange by more than [`MAX_CALIBRATION_OFFSET_M`] from the nominal model at any of a set
    /// of test configurations is rejected (wrong model, or a broken file).
    pub fn from_toml_str(text: &str) -> Result<Self, KinError> {
        let file: CalibrationFile = toml::from_str(text).map_err(|e| KinError::Calibration {
            message: e.to_string().trim_end().replace('\n', " "),
        })?;
        let model: Model = file.model.parse()?;
        let nominal = DhParams::nominal(&model.spec().geometry);
        let dh = match (file.dh, file.delta) {
            (Some(dh), None) => DhParams::from(dh),
            (None, Some(delta)) => nominal.plus(&DhParams::from(delta)),
            (Some(_), Some(_)) => {
                return Err(KinError::Calibration {
                    message: "give either [dh] (absolute values) or [delta], not both".into(),
                });
            }
            (None, None) => {
                return Err(KinError::Calibration {
                    message: "missing [dh] (absolute values) or [delta] table".into(),
                });
            }
        };
        let cal = Self { model, dh };
        cal.validate()?;
        Ok(cal)
    }

    /// Checks the values are finite and the chain stays near the nominal model's.
    pub fn validate(&self) -> Result<(), KinError> {
        self.dh.check_finite()?;
        let nominal = DhParams::nominal(&self.model.spec().geometry);
        let test_configs = [
            [0.0; 6],
            [0.3, -1.2, 1.4, -0.9, 1.1, 0.4],
            [-2.0, -2.3, -1.0, 2.0, -0.7, 2.5],
            [1.5, -0.4, 2.2, 0.6, 1.9, -1.3],
        ];
        for q in &test_configs {
            let off = (self.dh.flange(q).translation.vector - nominal.flange(q).translation.vector)
                .norm();
            if off > MAX_CALIBRATION_OFFSET_M {
                return Err(KinError::Calibration {
                    message: format!(
                        "the calibrated chain puts the flange {off:.3} m from the nominal {} at \
                         q = {q:?} (more than {MAX_CALIBRATION_OFFSET_M} m): wrong model or \
                         broken values",
                        self.model
                    ),
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn nominal_chain_matches_published_sanity_values() {
        let ur5 = DhParams::nominal(&Model::Ur5.spec().geometry);
        let t = ur5.flange(&[0.0, -FRAC_PI_2, FRAC_PI_2, 0.0, FRAC_PI_2, 0.0]);
        assert_relative_eq!(t.translation.x, -0.47455, epsilon = 1e-12);
        assert_relative_eq!(t.translation.y, -0.10915, epsilon = 1e-12);
        assert_relative_eq!(t.translation.z, 0.419509, epsilon = 1e-12);
        let ur5e = DhParams::nominal(&Model::Ur5e.spec().geometry);
        let t = ur5e.flange(&[0.0; 6]);
        assert_relative_eq!(t.translation.x, -0.8172, epsilon = 1e-12);
        assert_relative_eq!(t.translation.y, -0.2329, epsilon = 1e-12);
        assert_relative_eq!(t.translation.z, 0.0628, epsilon = 1e-12);
    }

    #[test]
    fn ur10_simulated_robot_reference_positions() {
        // Positions a simulated UR10 controller reported (from ur_calibration's tests).
        let ur10 = DhParams::nominal(&Model::Ur10.spec().geometry);
        let t = ur10.flange(&[
            -1.6007002035724085,
            -1.7271001974688929,
            -2.2029998938189905,
            -0.8079999128924769,
            1.5951000452041626,
            -0.03099996248354131,
        ]);
        assert_relative_eq!(t.translation.x, -0.179925914147547, epsilon = 1e-9);
        assert_relative_eq!(t.translation.y, -0.606869755162764, epsilon = 1e-9);
        assert_relative_eq!(t.translation.z, 0.230789102067257, epsilon = 1e-9);
    }

    #[test]
    fn frames_end_at_flange() {
        let dh = DhParams::nominal(&Model::Ur3e.spec().geometry);
        let q = [0.1, -0.7, 1.2, 0.3, -1.1, 2.0];
        let frames = dh.frames(&q);
        assert_eq!(frames[0], Isometry3::identity());
        let f = dh.flange(&q);
        assert!((frames[6].translation.vector - f.translation.vector).norm() < 1e-15);
        // Frame 1 sits on the base axis at the shoulder height d1.
        assert_relative_eq!(frames[1].translation.z, 0.15185, epsilon = 1e-15);
        assert_relative_eq!(frames[1].translation.x, 0.0, epsilon = 1e-15);
    }

    const DELTA_TOML: &str = r#"
model = "ur10"
# A real factory calibration (values from ur_calibration's test data): huge compensating d's
# on the parallel axes, theta offsets beyond 2π.
[delta]
d = [-0.000144894975118076141, 303.469135666158195, -309.88394307789747, 6.41459904397394975, -4.48232900190081995e-05, -0.00087071402790364627]
a = [0.000108651068627930392, 0.240324175250532346, 0.00180628180213493472, 2.63076149165684402e-05, 3.96638632500012715e-06, 0]
theta = [1.59613525316931737e-07, -0.917209621528830232, 7.12936131346499469, 0.0710299029424392298, -1.64258976526054923e-06, 9.17286101034808787e-08]
alpha = [-0.000444781952841921679, -0.00160215112531214153, 0.00631917793331091861, -0.00165055247340828437, 0.000763682515545038854, 0]
"#;

    #[test]
    fn parses_real_delta_calibration_and_stays_near_nominal() {
        let cal = DhCalibration::from_toml_str(DELTA_TOML).unwrap();
        assert_eq!(cal.model, Model::Ur10);
        assert_relative_eq!(cal.dh.d[1], 303.469_135_666_158_2, epsilon = 1e-12);
        let nominal = DhParams::nominal(&Model::Ur10.spec().geometry);
        let q = [0.4, -1.0, 1.3, -0.2, 0.8, 0.1];
        let off =
            (cal.dh.flange(&q).translation.vector - nominal.flange(&q).translation.vector).norm();
        assert!(off > 1e-4 && off < 0.02, "calibration offset {off}");
    }

    #[test]
    fn rejects_bad_files_with_a_reason() {
        let unknown_key = DELTA_TOML.replace("alpha =", "alfa =");
        let err = DhCalibration::from_toml_str(&unknown_key).unwrap_err();
        assert!(err.to_string().contains("alfa"), "{err}");
        assert!(err.to_string().contains("line"), "{err}");

        let wrong_model = DELTA_TOML.replace("ur10", "ur3");
        let err = DhCalibration::from_toml_str(&wrong_model).unwrap_err();
        assert!(err.to_string().contains("wrong model"), "{err}");

        let err = DhCalibration::from_toml_str("model = \"ur5\"\n").unwrap_err();
        assert!(err.to_string().contains("missing [dh]"), "{err}");

        let err = DhCalibration::from_toml_str(&DELTA_TOML.replace("ur10", "ur11")).unwrap_err();
        assert!(matches!(err, KinError::UnknownModel { .. }), "{err}");

        let short = DELTA_TOML.replace("d = [-0.000144894975118076141, ", "d = [");
        let err = DhCalibration::from_toml_str(&short).unwrap_err();
        assert!(err.to_string().contains("line"), "{err}");
    }
}
