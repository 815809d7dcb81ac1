//! Step 7: the pose from identified fiducials. Least-squares rigid registration (Kabsch/Arun,
//! with the reflection guard) and the seed paper's three-point frame, for comparison.

use mocomp_geom::nalgebra::{
    Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3,
};

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

/// The frame the seed paper builds from three points: origin at the first, x towards the second,
/// y in the plane of the third (Gram–Schmidt), z = x × y.
fn frame(p: &[Point3<f64>; 3]) -> Option<Isometry3<f64>> {
    let ex = (p[1] - p[0]).try_normalize(1e-12)?;
    let v = p[2] - p[0];
    let ey = (v - ex * ex.dot(&v)).try_normalize(1e-12)?;
    let ez = ex.cross(&ey);
    let r = Matrix3::from_columns(&[ex, ey, ez]);
    Some(Isometry3::from_parts(
        Translation3::from(p[0].coords),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    ))
}

/// The seed paper's pose: the three-point frame of the measured points times the inverse of the
/// model's. Uses the three points unequally and averages nothing; kept for comparison.
pub fn three_point(
    model: &[Point3<f64>; 3],
    measured: &[Point3<f64>; 3],
) -> Option<Isometry3<f64>> {
    Some(frame(measured)? * frame(model)?.inverse())
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_geom::{quat_from_rotvec, rotation_error, translation_error};

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

    #[test]
    fn three_point_frame_is_exact_without_noise() {
        let m = [
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(0.06, 0.01, 0.0),
            Point3::new(0.01, 0.05, 0.02),
        ];
        let t = pose();
        let q = [t * m[0], t * m[1], t * m[2]];
        let est = three_point(&m, &q).unwrap();
        assert!(rotation_error(&est, &t) < 1e-12 && translation_error(&est, &t) < 1e-12);
    }
}
