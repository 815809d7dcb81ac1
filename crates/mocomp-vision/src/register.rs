//! Step 7: the pose from identified fiducials. Least-squares rigid registration (Kabsch/Arun,
//! with the reflection guard) and the seed paper's three-point frame, for comparison.

pub use mocomp_geom::fit::{kabsch, rms};
use mocomp_geom::nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion};

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
    use mocomp_geom::nalgebra::Vector3;
    use mocomp_geom::{quat_from_rotvec, rotation_error, translation_error};

    fn pose() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 1.1),
            quat_from_rotvec(&Vector3::new(0.4, -1.2, 2.5)),
        )
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
