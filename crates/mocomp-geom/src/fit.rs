//! Least-squares rigid registration of paired points (Kabsch/Arun, with the reflection guard):
//! a marker's pose from its fiducials, the patient's head from anatomical landmarks.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// `measured_from_model` minimising `Σ |T·pᵢ − qᵢ|²`, with its RMS residual (the fiducial
/// registration error), or `None` when the points do not determine a rotation (fewer than 3, or
/// collinear).
pub fn kabsch(model: &[Point3<f64>], measured: &[Point3<f64>]) -> Option<(Isometry3<f64>, f64)> {
    let n = model.len();
    if n < 3 || n != measured.len() {
        return None;
    }
    let pm: Vector3<f64> = model.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n as f64;
    let qm: Vector3<f64> = measured.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n as f64;
    let mut h = Matrix3::zeros();
    for (p, q) in model.iter().zip(measured) {
        h += (p.coords - pm) * (q.coords - qm).transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut s = svd.singular_values;
    s.as_mut_slice().sort_by(|a, b| b.total_cmp(a));
    if s[1] <= 1e-12 * s[0].max(1e-300) {
        return None; // collinear
    }
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant().signum();
    let r = v * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * u.transpose();
    let rot = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    let t = qm - rot * pm;
    let pose = Isometry3::from_parts(Translation3::from(t), rot);
    Some((pose, rms(&pose, model, measured)))
}

/// RMS distance between the transformed model points and the measured ones.
pub fn rms(pose: &Isometry3<f64>, model: &[Point3<f64>], measured: &[Point3<f64>]) -> f64 {
    let n = model.len().max(1) as f64;
    (model
        .iter()
        .zip(measured)
        .map(|(p, q)| (pose * p - q).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::{quat_from_rotvec, rotation_error, translation_error};

    fn pose() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 1.1),
            quat_from_rotvec(&Vector3::new(0.4, -1.2, 2.5)),
        )
    }

    #[test]
    fn kabsch_recovers_pose_exactly_including_planar_markers() {
        let planar = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.05, 0.0, 0.0),
            Point3::new(0.0, 0.07, 0.0),
        ];
        let t = pose();
        let q: Vec<_> = planar.iter().map(|p| t * p).collect();
        let (est, fre) = kabsch(&planar, &q).unwrap();
        assert!(rotation_error(&est, &t) < 1e-12 && translation_error(&est, &t) < 1e-12);
        assert!(fre < 1e-12);
        // Mirrored measurements of a non-planar marker: the guard keeps a proper rotation, which
        // cannot fit a reflection, so the FRE is large instead of the fit being a mirror.
        let model = [
            planar[0],
            planar[1],
            planar[2],
            Point3::new(0.01, 0.01, 0.04),
        ];
        let mirrored: Vec<_> = model
            .iter()
            .map(|p| {
                let q = t * p;
                Point3::new(-q.x, q.y, q.z)
            })
            .collect();
        let (m, fre) = kabsch(&model, &mirrored).unwrap();
        assert!((m.rotation.to_rotation_matrix().matrix().determinant() - 1.0).abs() < 1e-12);
        assert!(fre > 0.005, "{fre}");
        let line = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.1, 0.0, 0.0),
            Point3::new(0.2, 0.0, 0.0),
        ];
        assert!(kabsch(&line, &line).is_none());
    }
}
