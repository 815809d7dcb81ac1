//! Conversions between [`Isometry3`] and the representations found at mocomp's edges: the UR pose
//! vector `[x, y, z, rx, ry, rz]` (metres, rotation vector; RTDE and URScript), 4×4 homogeneous
//! matrices (metres, or millimetres where a format demands it), row arrays for JSON, and
//! quaternions in `w, x, y, z` order (the way trackers report).

use crate::error::GeomError;
use crate::units::{m_to_mm, mm_to_m};
use nalgebra::{
    Isometry3, Matrix3, Matrix4, Quaternion, Rotation3, Translation3, UnitQuaternion, Vector3,
};
use std::f64::consts::{PI, TAU};

/// Default tolerance for accepting a rotation block as orthonormal (max |RᵀR − I|) and the last row
/// of a homogeneous matrix as `[0, 0, 0, 1]`. Loose enough for matrices printed with 6 decimals.
pub const RIGID_TOLERANCE: f64 = 1e-5;

fn check_finite(what: &'static str, values: &[f64]) -> Result<(), GeomError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(index) => Err(GeomError::NonFinite {
            what,
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

/// The rotation vector (axis × angle, angle in `[0, π]`) of a unit quaternion.
///
/// Computed as `2·atan2(|v|, w)` on the hemisphere `w ≥ 0`, which keeps full precision near 0 and
/// near π (where the trace formula `acos((tr R − 1)/2)` loses half the digits). At exactly π both
/// `±π·axis` describe the rotation; the one whose first non-zero component is positive is returned,
/// so the result is deterministic.
pub fn rotvec_from_quat(q: &UnitQuaternion<f64>) -> Vector3<f64> {
    let (mut w, mut v) = (q.w, q.imag());
    if w < 0.0 {
        w = -w;
        v = -v;
    }
    let s = v.norm();
    if s == 0.0 {
        return Vector3::zeros();
    }
    if w == 0.0 {
        // Exactly π: canonical sign.
        let first = v.iter().copied().find(|c| *c != 0.0).unwrap_or(1.0);
        if first < 0.0 {
            v = -v;
        }
    }
    let angle = 2.0 * s.atan2(w);
    v * (angle / s)
}

/// The unit quaternion of a rotation vector (axis × angle, any angle).
pub fn quat_from_rotvec(rotvec: &Vector3<f64>) -> UnitQuaternion<f64> {
    let theta = rotvec.norm();
    let half = 0.5 * theta;
    // sin(θ/2)/θ, with its series where θ underflows the division.
    let k = if theta < 1e-8 {
        0.5 - theta * theta / 48.0
    } else {
        half.sin() / theta
    };
    UnitQuaternion::new_unchecked(Quaternion::new(
        half.cos(),
        rotvec.x * k,
        rotvec.y * k,
        rotvec.z * k,
    ))
}

/// The UR pose vector `[x, y, z, rx, ry, rz]` (metres, rotation vector with angle in `[0, π]`) of a
/// transform, as RTDE's `actual_TCP_pose` and URScript's `p[...]` use it.
pub fn ur_pose_from_iso(iso: &Isometry3<f64>) -> [f64; 6] {
    let t = iso.translation.vector;
    let r = rotvec_from_quat(&iso.rotation);
    [t.x, t.y, t.z, r.x, r.y, r.z]
}

/// Like [`ur_pose_from_iso`], but picks, among the rotation vectors of the same rotation
/// (`θ·u` and `(θ − 2π)·u`), the one nearest `reference` (a previous pose vector's `rx, ry, rz`).
///
/// A rotation vector jumps when the angle passes π; anything that interpolates or differentiates
/// pose vectors (URScript `servoc`, a filter on pose vectors) needs the continuous one.
pub fn ur_pose_near(iso: &Isometry3<f64>, reference: &[f64; 3]) -> [f64; 6] {
    let mut p = ur_pose_from_iso(iso);
    let r = Vector3::new(p[3], p[4], p[5]);
    let reference = Vector3::new(reference[0], reference[1], reference[2]);
    let theta = r.norm();
    if theta > 0.0 {
        let alt = r * ((theta - TAU) / theta);
        if (alt - reference).norm() < (r - reference).norm() {
            p[3] = alt.x;
            p[4] = alt.y;
            p[5] = alt.z;
        }
    } else if reference.norm() > PI {
        // Identity: the equivalent vector nearest a long reference is 2π along its axis.
        let alt = reference * (TAU / reference.norm());
        p[3] = alt.x;
        p[4] = alt.y;
        p[5] = alt.z;
    }
    p
}

/// The transform of a UR pose vector `[x, y, z, rx, ry, rz]` (metres, rotation vector of any
/// length). Fails on NaN or infinite components, naming the index.
pub fn iso_from_ur_pose(pose: &[f64; 6]) -> Result<Isometry3<f64>, GeomError> {
    check_finite("UR pose vector", pose)?;
    Ok(Isometry3::from_parts(
        Translation3::new(pose[0], pose[1], pose[2]),
        quat_from_rotvec(&Vector3::new(pose[3], pose[4], pose[5])),
    ))
}

/// The 4×4 homogeneous matrix of a transform (translation in metres).
pub fn matrix_from_iso(iso: &Isometry3<f64>) -> Matrix4<f64> {
    iso.to_homogeneous()
}

/// The 4×4 homogeneous matrix of a transform with its translation in millimetres.
pub fn matrix_mm_from_iso(iso: &Isometry3<f64>) -> Matrix4<f64> {
    let mut m = iso.to_homogeneous();
    for r in 0..3 {
        m[(r, 3)] = m_to_mm(m[(r, 3)]);
    }
    m
}

/// The transform of a 4×4 homogeneous matrix (translation in metres).
///
/// The matrix must be finite, its last row `[0, 0, 0, 1]` and its rotation block orthonormal with
/// a positive determinant, each within `tolerance` (see [`RIGID_TOLERANCE`]); the rotation is then
/// projected exactly onto SO(3). Each failed check is its own error.
pub fn iso_from_matrix(m: &Matrix4<f64>, tolerance: f64) -> Result<Isometry3<f64>, GeomError> {
    let rowmajor: Vec<f64> = m.transpose().iter().copied().collect();
    check_finite("homogeneous matrix", &rowmajor)?;
    let row = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    if row[0].abs() > tolerance
        || row[1].abs() > tolerance
        || row[2].abs() > tolerance
        || (row[3] - 1.0).abs() > tolerance
    {
        return Err(GeomError::BadBottomRow { row });
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let det = r.determinant();
    if det <= 0.0 {
        return Err(GeomError::Reflection { det });
    }
    let deviation = (r.transpose() * r - Matrix3::identity()).amax();
    if deviation > tolerance {
        return Err(GeomError::NotOrthonormal {
            deviation,
            tolerance,
        });
    }
    let rot = orthonormalize(&r)?;
    Ok(Isometry3::from_parts(
        Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]),
        UnitQuaternion::from_rotation_matrix(&rot),
    ))
}

/// The transform of a 4×4 homogeneous matrix whose translation is in millimetres (converted to
/// metres here). Checks as [`iso_from_matrix`].
pub fn iso_from_matrix_mm(m: &Matrix4<f64>, tolerance: f64) -> Result<Isometry3<f64>, GeomError> {
    let mut metres = *m;
    for r in 0..3 {
        metres[(r, 3)] = mm_to_m(m[(r, 3)]);
    }
    iso_from_matrix(&metres, tolerance)
}

/// The homogeneous matrix as four rows (the JSON layout `[[r00, r01, r02, x], ...]`), metres.
pub fn rows_from_iso(iso: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = iso.to_homogeneous();
    let mut rows = [[0.0; 4]; 4];
    for (r, row) in rows.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = m[(r, c)];
        }
    }
    rows
}

/// The transform of a homogeneous matrix given as four rows, metres. Checks as [`iso_from_matrix`].
pub fn iso_from_rows(rows: &[[f64; 4]; 4], tolerance: f64) -> Result<Isometry3<f64>, GeomError> {
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    iso_from_matrix(&m, tolerance)
}

/// The transform of a translation (metres) and a quaternion in `w, x, y, z` order.
///
/// The quaternion is normalised; it must be finite and its norm within `tolerance` of 1 (a far-off
/// norm means the numbers are not a rotation, e.g. columns read in the wrong order).
pub fn iso_from_wxyz(
    translation: &[f64; 3],
    wxyz: &[f64; 4],
    tolerance: f64,
) -> Result<Isometry3<f64>, GeomError> {
    check_finite("translation", translation)?;
    check_finite("quaternion (w, x, y, z)", wxyz)?;
    let q = Quaternion::new(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    let norm = q.norm();
    if (norm - 1.0).abs() > tolerance || norm == 0.0 {
        return Err(GeomError::QuaternionNorm { norm, tolerance });
    }
    Ok(Isometry3::from_parts(
        Translation3::new(translation[0], translation[1], translation[2]),
        UnitQuaternion::from_quaternion(q),
    ))
}

/// Translation (metres) and quaternion `w, x, y, z` (with `w ≥ 0`) of a transform.
pub fn wxyz_from_iso(iso: &Isometry3<f64>) -> ([f64; 3], [f64; 4]) {
    let t = iso.translation.vector;
    let q = iso.rotation.quaternion();
    let s = if q.w < 0.0 { -1.0 } else { 1.0 };
    ([t.x, t.y, t.z], [s * q.w, s * q.i, s * q.j, s * q.k])
}

/// The rotation nearest (in Frobenius norm) to a noisy 3×3 matrix: `U·diag(1, 1, det(UVᵀ))·Vᵀ`
/// from its SVD, so the result is a proper rotation even when the input is near a reflection.
///
/// Fails when the matrix is not finite or so close to rank 1 that the nearest rotation is not
/// unique.
pub fn orthonormalize(m: &Matrix3<f64>) -> Result<Rotation3<f64>, GeomError> {
    if let Some(index) = m.transpose().iter().position(|v| !v.is_finite()) {
        return Err(GeomError::NonFinite {
            what: "3×3 matrix",
            index,
            value: m[(index / 3, index % 3)],
        });
    }
    let svd = m.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(GeomError::RankDeficient {
            singular_values: [0.0; 3],
        });
    };
    let mut s = [
        svd.singular_values[0],
        svd.singular_values[1],
        svd.singular_values[2],
    ];
    s.sort_by(|a, b| b.total_cmp(a));
    // The nearest rotation is unique when the second-smallest singular value is not negligible.
    if s[1] <= s[0] * 1e-12 {
        return Err(GeomError::RankDeficient { singular_values: s });
    }
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        // Flip the direction of the smallest singular value.
        let smallest = (0..3)
            .min_by(|&i, &j| svd.singular_values[i].total_cmp(&svd.singular_values[j]))
            .unwrap_or(2);
        d[(smallest, smallest)] = -1.0;
    }
    Ok(Rotation3::from_matrix_unchecked(u * d * v_t))
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::Rotation3;
    use proptest::prelude::*;

    fn arb_rotvec() -> impl Strategy<Value = Vector3<f64>> {
        // Angles over [0, π] including the ends, axes anywhere.
        (
            -1.0..1.0f64,
            -1.0..1.0f64,
            -1.0..1.0f64,
            prop_oneof![0.0..PI, Just(PI), Just(0.0), (PI - 1e-6)..PI, 0.0..1e-9,],
        )
            .prop_filter("axis", |(x, y, z, _)| x * x + y * y + z * z > 1e-4)
            .prop_map(|(x, y, z, a)| Vector3::new(x, y, z).normalize() * a)
    }

    fn arb_iso() -> impl Strategy<Value = Isometry3<f64>> {
        (arb_rotvec(), -2.0..2.0f64, -2.0..2.0f64, -2.0..2.0f64).prop_map(|(r, x, y, z)| {
            Isometry3::from_parts(Translation3::new(x, y, z), quat_from_rotvec(&r))
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 2000, rng_seed: proptest::test_runner::RngSeed::Fixed(12), failure_persistence: None, ..ProptestConfig::default() })]

        #[test]
        fn ur_pose_round_trip(iso in arb_iso()) {
            let p = ur_pose_from_iso(&iso);
            let back = iso_from_ur_pose(&p).unwrap();
            prop_assert!(crate::rotation_error(&iso, &back) < 1e-14);
            prop_assert!(crate::translation_error(&iso, &back) < 1e-15);
            let angle = Vector3::new(p[3], p[4], p[5]).norm();
            prop_assert!(angle <= PI + 1e-15);
        }

        #[test]
        fn rotvec_recovers_angle_near_pi(rv in arb_rotvec()) {
            // The rotation vector of the quaternion of rv is rv (or −rv at exactly π).
            let back = rotvec_from_quat(&quat_from_rotvec(&rv));
            let angle = rv.norm();
            if angle < PI - 1e-9 {
                prop_assert!((back - rv).norm() < 1e-14 * (1.0 + angle), "{back} vs {rv}");
            } else {
                prop_assert!((back - rv).norm() < 1e-12 || (back + rv).norm() < 1e-12);
            }
        }

        #[test]
        fn matrix_round_trips(iso in arb_iso()) {
            let back = iso_from_matrix(&matrix_from_iso(&iso), RIGID_TOLERANCE).unwrap();
            prop_assert!(crate::rotation_error(&iso, &back) < 1e-14);
            prop_assert!(crate::translation_error(&iso, &back) < 1e-15);
            let mm = matrix_mm_from_iso(&iso);
            prop_assert!((mm[(0, 3)] - 1000.0 * iso.translation.x).abs() < 1e-12);
            let back = iso_from_matrix_mm(&mm, RIGID_TOLERANCE).unwrap();
            prop_assert!(crate::translation_error(&iso, &back) < 1e-15);
            let rows = rows_from_iso(&iso);
            let back = iso_from_rows(&rows, RIGID_TOLERANCE).unwrap();
            prop_assert!(crate::rotation_error(&iso, &back) < 1e-14);
        }

        #[test]
        fn quaternion_round_trip_and_sign_invariance(iso in arb_iso()) {
            let (t, q) = wxyz_from_iso(&iso);
            prop_assert!(q[0] >= 0.0);
            let back = iso_from_wxyz(&t, &q, 1e-6).unwrap();
            prop_assert!(crate::rotation_error(&iso, &back) < 1e-14);
            let neg = [-q[0], -q[1], -q[2], -q[3]];
            let back = iso_from_wxyz(&t, &neg, 1e-6).unwrap();
            prop_assert!(crate::rotation_error(&iso, &back) < 1e-14);
        }
    }

    #[test]
    fn rotvec_at_exactly_pi_is_canonical() {
        for axis in [
            Vector3::x(),
            -Vector3::x(),
            Vector3::new(0.0, -1.0, 1.0).normalize(),
        ] {
            let q = UnitQuaternion::new_unchecked(Quaternion::new(0.0, axis.x, axis.y, axis.z));
            let rv = rotvec_from_quat(&q);
            assert_relative_eq!(rv.norm(), PI, epsilon = 1e-15);
            let first = rv.iter().copied().find(|c| c.abs() > 0.0).unwrap();
            assert!(first > 0.0, "{rv}");
        }
    }

    #[test]
    fn rotation_matrix_near_pi_keeps_precision() {
        // The trace formula would give an angle error ~1e-8 here; the quaternion path keeps 1e-15.
        let angle = PI - 1e-7;
        let axis = Vector3::new(0.3, -0.5, 0.8).normalize();
        let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
        let mut m = Matrix4::identity();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(r.matrix());
        let iso = iso_from_matrix(&m, RIGID_TOLERANCE).unwrap();
        let p = ur_pose_from_iso(&iso);
        let rv = Vector3::new(p[3], p[4], p[5]);
        assert_relative_eq!(rv.norm(), angle, epsilon = 1e-13);
        assert_relative_eq!(rv.normalize(), axis, epsilon = 1e-9);
    }

    #[test]
    fn ur_pose_near_picks_continuous_vector() {
        let axis = Vector3::new(0.0, 0.0, 1.0);
        let iso = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.0),
            quat_from_rotvec(&(axis * (PI - 0.01))),
        );
        // Reference just past π on the same axis: the 2π-shifted vector (−(π+0.01) in the other
        // direction... expressed as (θ−2π)·u) is the closer one.
        let p = ur_pose_near(&iso, &[0.0, 0.0, -(PI - 0.02)]);
        assert_relative_eq!(p[5], (PI - 0.01) - TAU, epsilon = 1e-12);
        let p = ur_pose_near(&iso, &[0.0, 0.0, PI - 0.02]);
        assert_relative_eq!(p[5], PI - 0.01, epsilon = 1e-12);
        // Whatever is picked is the same rotation.
        let back = iso_from_ur_pose(&ur_pose_near(&iso, &[0.0, 0.0, -3.0])).unwrap();
        assert!(crate::rotation_error(&iso, &back) < 1e-14);
    }

    #[test]
    fn paper_sanity_values_in_millimetres() {
        // A matrix in mm, as the paper prints E2_T_E1,g (rounded to 4 decimals: loose tolerance).
        let m = Matrix4::new(
            0.8725, 0.159, 0.4619, 9.5626, -0.4253, -0.2179, 0.8784, -160.5035, 0.2404, -0.9629,
            -0.1225, 412.4959, 0.0, 0.0, 0.0, 1.0,
        );
        let iso = iso_from_matrix_mm(&m, 1e-3).unwrap();
        assert_relative_eq!(iso.translation.vector.z, 0.4124959, epsilon = 1e-12);
        // Its rotation block is 4-decimal rounded: the strict default tolerance rejects it.
        let err = iso_from_matrix_mm(&m, 1e-5).unwrap_err();
        assert!(matches!(err, GeomError::NotOrthonormal { .. }), "{err}");
    }

    #[test]
    fn bad_inputs_are_named() {
        let err = iso_from_ur_pose(&[0.0, 0.0, f64::NAN, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(
            matches!(
                err,
                GeomError::NonFinite {
                    what: "UR pose vector",
                    index: 2,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("element 2"));

        let mut m = Matrix4::identity();
        m[(3, 0)] = 0.5;
        assert!(matches!(
            iso_from_matrix(&m, RIGID_TOLERANCE),
            Err(GeomError::BadBottomRow { .. })
        ));
        let mut m = Matrix4::identity();
        m[(2, 2)] = -1.0;
        assert!(matches!(
            iso_from_matrix(&m, RIGID_TOLERANCE),
            Err(GeomError::Reflection { .. })
        ));
        let mut m = Matrix4::identity();
        m[(0, 0)] = 1.1;
        assert!(matches!(
            iso_from_matrix(&m, RIGID_TOLERANCE),
            Err(GeomError::NotOrthonormal { .. })
        ));
        let mut m = Matrix4::identity();
        m[(1, 3)] = f64::INFINITY;
        let err = iso_from_matrix(&m, RIGID_TOLERANCE).unwrap_err();
        assert!(
            matches!(err, GeomError::NonFinite { index: 7, .. }),
            "row-major index: {err}"
        );
        assert!(matches!(
            iso_from_wxyz(&[0.0; 3], &[0.0; 4], 1e-3),
            Err(GeomError::QuaternionNorm { .. })
        ));
        assert!(matches!(
            iso_from_wxyz(&[0.0; 3], &[2.0, 0.0, 0.0, 0.0], 1e-3),
            Err(GeomError::QuaternionNorm { .. })
        ));
    }
}
