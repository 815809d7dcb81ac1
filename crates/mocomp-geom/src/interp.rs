//! SE(3) interpolation, averaging and orthonormalisation.

use crate::error::GeomError;
use crate::pose::{quat_from_rotvec, rotvec_from_quat};
use nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion, Vector3};

/// Spherical linear interpolation between two orientations along the shorter arc, `t ∈ [0, 1]`
/// (values outside extrapolate). Never panics: at 180° apart it picks a deterministic arc.
pub fn slerp(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>, t: f64) -> UnitQuaternion<f64> {
    // a · exp(t · log(a⁻¹ b)), with log taken on the w ≥ 0 hemisphere (the short arc).
    let rel = rotvec_from_quat(&(a.inverse() * b));
    a * quat_from_rotvec(&(rel * t))
}

/// Interpolates two transforms: translation linearly, rotation by [`slerp`] (the decoupled
/// interpolation that UR's linear moves use). `t = 0` gives `a`, `t = 1` gives `b`.
pub fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, t: f64) -> Isometry3<f64> {
    let ta = a.translation.vector;
    let tb = b.translation.vector;
    Isometry3::from_parts(
        Translation3::from(ta + (tb - ta) * t),
        slerp(&a.rotation, &b.rotation, t),
    )
}

/// Weighted mean of transforms: the weighted mean of the translations, and for the rotation the
/// quaternion (chordal L2) mean of Markley et al. 2007, i.e. the principal eigenvector of
/// `Σ wᵢ qᵢ qᵢᵀ`, which is insensitive to the sign of each quaternion.
///
/// `weights` defaults to equal weights. Fails on an empty set, a count mismatch, negative or
/// non-finite weights, a zero weight sum, and rotations so spread that the mean is not unique.
pub fn average(
    poses: &[Isometry3<f64>],
    weights: Option<&[f64]>,
) -> Result<Isometry3<f64>, GeomError> {
    if poses.is_empty() {
        return Err(GeomError::Empty);
    }
    if let Some(w) = weights {
        if w.len() != poses.len() {
            return Err(GeomError::WeightCount {
                poses: poses.len(),
                weights: w.len(),
            });
        }
        if let Some(index) = w.iter().position(|v| !v.is_finite() || *v < 0.0) {
            return Err(GeomError::BadWeight {
                index,
                value: w[index],
            });
        }
    }
    let weight = |i: usize| weights.and_then(|w| w.get(i).copied()).unwrap_or(1.0);
    let total: f64 = (0..poses.len()).map(weight).sum();
    if total <= 0.0 {
        return Err(GeomError::ZeroWeightSum);
    }
    let mut t = Vector3::zeros();
    let mut scatter = Matrix4::zeros();
    for (i, p) in poses.iter().enumerate() {
        let w = weight(i) / total;
        t += p.translation.vector * w;
        let q = p.rotation.as_vector();
        scatter += q * q.transpose() * w;
    }
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2, 3];
    order.sort_by(|&i, &j| eig.eigenvalues[j].total_cmp(&eig.eigenvalues[i]));
    let gap = eig.eigenvalues[order[0]] - eig.eigenvalues[order[1]];
    if gap < 1e-9 {
        return Err(GeomError::AmbiguousMean { gap });
    }
    let v = eig.eigenvectors.column(order[0]);
    // Quaternion storage order in nalgebra is (i, j, k, w).
    let q = nalgebra::Quaternion::new(v[3], v[0], v[1], v[2]);
    Ok(Isometry3::from_parts(
        Translation3::from(t),
        UnitQuaternion::from_quaternion(q),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::{rotation_error, translation_error};
    use crate::pose::orthonormalize;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix3, Rotation3};
    use proptest::prelude::*;
    use std::f64::consts::PI;

    fn iso(t: [f64; 3], rv: [f64; 3]) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(t[0], t[1], t[2]),
            quat_from_rotvec(&Vector3::new(rv[0], rv[1], rv[2])),
        )
    }

    #[test]
    fn interpolate_endpoints_and_midpoint() {
        let a = iso([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]);
        let b = iso([1.0, 2.0, 3.0], [0.0, 0.0, 1.2]);
        assert!(translation_error(&interpolate(&a, &b, 0.0), &a) < 1e-15);
        assert!(rotation_error(&interpolate(&a, &b, 1.0), &b) < 1e-15);
        let m = interpolate(&a, &b, 0.5);
        assert_relative_eq!(m.translation.vector, Vector3::new(0.5, 1.0, 1.5));
        assert_relative_eq!(rotation_error(&a, &m), 0.6, epsilon = 1e-14);
        assert_relative_eq!(rotation_error(&m, &b), 0.6, epsilon = 1e-14);
    }

    #[test]
    fn slerp_takes_short_arc_and_survives_180_degrees() {
        let a = UnitQuaternion::identity();
        // b given with a negative w: the short arc is still 0.4 rad.
        let b = UnitQuaternion::new_unchecked(
            -quat_from_rotvec(&Vector3::new(0.4, 0.0, 0.0)).into_inner(),
        );
        let m = slerp(&a, &b, 0.5);
        assert_relative_eq!(m.angle(), 0.2, epsilon = 1e-14);
        let half_turn = quat_from_rotvec(&Vector3::new(0.0, PI, 0.0));
        let m = slerp(&a, &half_turn, 0.5);
        assert_relative_eq!(m.angle(), PI / 2.0, epsilon = 1e-14);
    }

    #[test]
    fn average_of_symmetric_set_is_centre() {
        let centre = iso([0.1, 0.2, 0.3], [0.3, -0.2, 0.9]);
        let mut poses = Vec::new();
        for d in [
            [0.05, 0.0, 0.0],
            [-0.05, 0.0, 0.0],
            [0.0, 0.05, 0.0],
            [0.0, -0.05, 0.0],
        ] {
            poses.push(centre * iso([d[0], d[1], d[2]], [d[0], d[1], d[2]]));
        }
        let mean = average(&poses, None).unwrap();
        assert!(translation_error(&mean, &centre) < 1e-15);
        assert!(
            rotation_error(&mean, &centre) < 1e-6,
            "{}",
            rotation_error(&mean, &centre)
        );
        // Weights pull the mean: all weight on one pose gives that pose.
        let mean = average(&poses, Some(&[0.0, 1.0, 0.0, 0.0])).unwrap();
        assert!(rotation_error(&mean, &poses[1]) < 1e-14);
        assert!(translation_error(&mean, &poses[1]) < 1e-15);
    }

    #[test]
    fn average_rejects_bad_input() {
        let p = Isometry3::identity();
        assert_eq!(average(&[], None), Err(GeomError::Empty));
        assert!(matches!(
            average(&[p], Some(&[1.0, 2.0])),
            Err(GeomError::WeightCount { .. })
        ));
        assert!(matches!(
            average(&[p, p], Some(&[1.0, -2.0])),
            Err(GeomError::BadWeight { index: 1, .. })
        ));
        assert_eq!(
            average(&[p, p], Some(&[0.0, 0.0])),
            Err(GeomError::ZeroWeightSum)
        );
        let half = iso([0.0; 3], [PI, 0.0, 0.0]);
        assert!(matches!(
            average(&[p, half], None),
            Err(GeomError::AmbiguousMean { .. })
        ));
    }

    #[test]
    fn orthonormalize_fixes_reflection_and_rejects_rank_one() {
        let r = orthonormalize(&Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0))).unwrap();
        assert_relative_eq!(r.matrix().determinant(), 1.0, epsilon = 1e-14);
        let rank1 = Matrix3::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        assert!(matches!(
            orthonormalize(&rank1),
            Err(GeomError::RankDeficient { .. })
        ));
        let mut nan = Matrix3::identity();
        nan[(1, 2)] = f64::NAN;
        assert!(matches!(
            orthonormalize(&nan),
            Err(GeomError::NonFinite { index: 5, .. })
        ));
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 500, rng_seed: proptest::test_runner::RngSeed::Fixed(11), failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn orthonormalize_recovers_rotation_from_noise(
            rx in -3.0..3.0f64, ry in -3.0..3.0f64, rz in -3.0..3.0f64,
            noise in proptest::collection::vec(-1e-3..1e-3f64, 9),
        ) {
            let r = Rotation3::from_scaled_axis(Vector3::new(rx, ry, rz));
            let noisy = r.matrix() + Matrix3::from_iterator(noise.iter().copied());
            let fixed = orthonormalize(&noisy).unwrap();
            let m = fixed.matrix();
            prop_assert!((m.transpose() * m - Matrix3::identity()).amax() < 1e-13);
            prop_assert!((m.determinant() - 1.0).abs() < 1e-13);
            // Nearest rotation: within the noise level of the true one.
            prop_assert!(fixed.angle_to(&r) < 1e-2);
            prop_assert!((m - noisy).norm() <= (r.matrix() - noisy).norm() + 1e-12);
        }

        #[test]
        fn interpolation_is_geodesic(
            a in proptest::array::uniform3(-3.0..3.0f64), b in proptest::array::uniform3(-3.0..3.0f64),
            t in 0.0..1.0f64,
        ) {
            let pa = iso([0.0; 3], a);
            let pb = iso([1.0, 0.0, 0.0], b);
            let total = rotation_error(&pa, &pb);
            let m = interpolate(&pa, &pb, t);
            // Along the short geodesic, the angles from each end add up to the total.
            prop_assert!((rotation_error(&pa, &m) + rotation_error(&m, &pb) - total).abs() < 1e-9);
            prop_assert!((rotation_error(&pa, &m) - t * total).abs() < 1e-9);
        }
    }
}
