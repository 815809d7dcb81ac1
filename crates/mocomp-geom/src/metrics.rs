//! Pose error metrics: translation error, rotation angle error, and the seed paper's deviation
//! `d = ‖T_goal − T‖_F` on homogeneous matrices.

use crate::pose::rotvec_from_quat;
use crate::units::m_to_mm;
use nalgebra::Isometry3;

/// The length unit of the translation column when a metric mixes rotation and translation entries
/// (the Frobenius deviation). The paper's `d` (Fig. 11) uses millimetres.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LengthUnit {
    /// Translation entries in metres.
    Metre,
    /// Translation entries in millimetres (the paper's convention for `d`).
    Millimetre,
}

/// Distance between the origins of two transforms, metres.
#[inline]
pub fn translation_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    (a.translation.vector - b.translation.vector).norm()
}

/// Angle of the rotation between two transforms' orientations, radians in `[0, π]`.
///
/// Computed from the relative quaternion with `atan2`, so it is exact near 0 and near π.
#[inline]
pub fn rotation_error(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    rotvec_from_quat(&(a.rotation.inverse() * b.rotation)).norm()
}

/// The seed paper's deviation `d = ‖T_goal − T‖_F`: the Frobenius norm of the difference of the two
/// 4×4 homogeneous matrices, with translations expressed in `unit`.
///
/// It mixes a rotation part (dimensionless, at most `2√2`) and a translation part, so the number
/// means nothing without its unit: the paper's Fig. 11 uses millimetres.
pub fn frobenius_deviation(
    goal: &Isometry3<f64>,
    actual: &Isometry3<f64>,
    unit: LengthUnit,
) -> f64 {
    let dr = goal.rotation.to_rotation_matrix().into_inner()
        - actual.rotation.to_rotation_matrix().into_inner();
    let mut dt = goal.translation.vector - actual.translation.vector;
    if unit == LengthUnit::Millimetre {
        dt = dt.map(m_to_mm);
    }
    (dr.norm_squared() + dt.norm_squared()).sqrt()
}

/// Translation and rotation error of a pose against a goal, in the units the reports use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseError {
    /// Distance between origins, metres.
    pub translation_m: f64,
    /// Rotation angle, radians.
    pub rotation_rad: f64,
}

impl PoseError {
    /// The error of `actual` against `goal`.
    pub fn between(goal: &Isometry3<f64>, actual: &Isometry3<f64>) -> Self {
        Self {
            translation_m: translation_error(goal, actual),
            rotation_rad: rotation_error(goal, actual),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::quat_from_rotvec;
    use approx::assert_relative_eq;
    use nalgebra::{Translation3, Vector3};
    use std::f64::consts::PI;

    #[test]
    fn frobenius_matches_closed_form() {
        // For a pure rotation by θ, ‖R − I‖_F = 2√2·sin(θ/2); a translation of t adds t² (in unit²).
        let theta = 0.3;
        let goal = Isometry3::identity();
        let actual = Isometry3::from_parts(
            Translation3::new(0.003, 0.0, 0.004),
            quat_from_rotvec(&(Vector3::new(1.0, 2.0, -1.0).normalize() * theta)),
        );
        let rot = 2.0 * 2f64.sqrt() * (theta / 2.0).sin();
        let d_mm = frobenius_deviation(&goal, &actual, LengthUnit::Millimetre);
        assert_relative_eq!(d_mm, (rot * rot + 25.0).sqrt(), epsilon = 1e-12);
        let d_m = frobenius_deviation(&goal, &actual, LengthUnit::Metre);
        assert_relative_eq!(d_m, (rot * rot + 25e-6).sqrt(), epsilon = 1e-12);
        assert_relative_eq!(translation_error(&goal, &actual), 0.005, epsilon = 1e-15);
        assert_relative_eq!(rotation_error(&goal, &actual), theta, epsilon = 1e-14);
    }

    #[test]
    fn rotation_error_is_exact_near_pi_and_zero() {
        let axis = Vector3::new(0.2, 0.9, -0.4).normalize();
        for theta in [0.0, 1e-12, 1e-6, 1.0, PI - 1e-9, PI] {
            let a = Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.0),
                quat_from_rotvec(&(Vector3::new(0.0, 0.0, 0.7))),
            );
            let b = a * Isometry3::from_parts(
                Translation3::new(0.0, 0.0, 0.0),
                quat_from_rotvec(&(axis * theta)),
            );
            assert_relative_eq!(rotation_error(&a, &b), theta, epsilon = 1e-14);
        }
        let e = PoseError::between(&Isometry3::identity(), &Isometry3::identity());
        assert_eq!(e.translation_m, 0.0);
        assert_eq!(e.rotation_rad, 0.0);
    }
}
