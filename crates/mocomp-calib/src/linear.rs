//! The closed-form solvers of `M_i · X = Y · N_i` (`M = base_from_flange`, `N = tracker_from_marker`).
//!
//! Vectorisation is column-major: `vec(A·B·C) = (Cᵀ ⊗ A)·vec(B)`.

use crate::error::CalibError;
use crate::pairs::Pair;
use mocomp_geom::nalgebra::{
    Isometry3, Matrix3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3,
};
use mocomp_geom::orthonormalize;

type Mat24 = SMatrix<f64, 24, 24>;
type Vec24 = SVector<f64, 24>;

fn rotation_of(p: &Isometry3<f64>) -> Matrix3<f64> {
    p.rotation.to_rotation_matrix().into_inner()
}

fn iso(r: &Matrix3<f64>, t: &Vector3<f64>) -> Result<Isometry3<f64>, CalibError> {
    let rot = orthonormalize(r).map_err(|_| CalibError::Singular { method: "rotation" })?;
    Ok(Isometry3::from_parts(
        Translation3::from(*t),
        UnitQuaternion::from_rotation_matrix(&rot),
    ))
}

/// The seed paper's linear method (Li, Wang and Wu 2010): the 24 unknowns
/// `w = [vec R_X; vec R_Y; t_X; t_Y]` from
/// `R_M R_X − R_Y R_N = 0` and `R_M t_X − R_Y t_N − t_Y = −t_M` in least squares, both rotations
/// projected onto SO(3), then (with `resolve_translation`) the translations solved again with the
/// rotations fixed.
pub fn li(
    pairs: &[Pair],
    resolve_translation: bool,
) -> Result<(Isometry3<f64>, Isometry3<f64>), CalibError> {
    let mut ata = Mat24::zeros();
    let mut atb = Vec24::zeros();
    let mut row = [0.0f64; 24];
    let mut add = |row: &[f64; 24], rhs: f64| {
        // Rank-one update of the normal equations, skipping zeros (rows are sparse).
        for a in 0..24 {
            if row[a] == 0.0 {
                continue;
            }
            atb[a] += row[a] * rhs;
            for b in a..24 {
                ata[(a, b)] += row[a] * row[b];
            }
        }
    };
    for p in pairs {
        let rm = rotation_of(&p.base_from_flange);
        let rn = rotation_of(&p.tracker_from_marker);
        let tm = p.base_from_flange.translation.vector;
        let tn = p.tracker_from_marker.translation.vector;
        // Rotation: entry (r, c) of R_M R_X − R_Y R_N.
        for c in 0..3 {
            for r in 0..3 {
                row.fill(0.0);
                for k in 0..3 {
                    row[k + 3 * c] = rm[(r, k)]; // X[k, c]
                    row[9 + r + 3 * k] = -rn[(k, c)]; // Y[r, k]
                }
                add(&row, 0.0);
            }
        }
        // Translation: row r of R_M t_X − R_Y t_N − t_Y = −t_M.
        for r in 0..3 {
            row.fill(0.0);
            for k in 0..3 {
                row[18 + k] = rm[(r, k)];
                row[9 + r + 3 * k] = -tn[k];
            }
            row[21 + r] = -1.0;
            add(&row, -tm[r]);
        }
    }
    for a in 0..24 {
        for b in 0..a {
            ata[(a, b)] = ata[(b, a)];
        }
    }
    let w = ata
        .cholesky()
        .map(|c| c.solve(&atb))
        .ok_or(CalibError::Singular { method: "li" })?;
    let rx = Matrix3::from_column_slice(&w.as_slice()[0..9]);
    let ry = Matrix3::from_column_slice(&w.as_slice()[9..18]);
    let mut tx = Vector3::new(w[18], w[19], w[20]);
    let mut ty = Vector3::new(w[21], w[22], w[23]);
    let x = iso(&rx, &tx)?;
    let y = iso(&ry, &ty)?;
    if resolve_translation {
        (tx, ty) = translations(pairs, &y.rotation)?;
    }
    Ok((
        Isometry3::from_parts(Translation3::from(tx), x.rotation),
        Isometry3::from_parts(Translation3::from(ty), y.rotation),
    ))
}

/// Shah 2013: `K = Σ R_N ⊗ R_M` satisfies `K·vec(R_X) = n·vec(R_Y)`, so the leading singular
/// vectors of `K` give both rotations (scaled to determinant 1 and projected onto SO(3)); then the
/// translations by linear least squares.
pub fn shah(pairs: &[Pair]) -> Result<(Isometry3<f64>, Isometry3<f64>), CalibError> {
    let mut k = SMatrix::<f64, 9, 9>::zeros();
    for p in pairs {
        let rm = rotation_of(&p.base_from_flange);
        let rn = rotation_of(&p.tracker_from_marker);
        k += rn.kronecker(&rm);
    }
    let svd = k.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(CalibError::Singular { method: "shah" });
    };
    let s = svd.singular_values;
    let mut order: Vec<usize> = (0..9).collect();
    order.sort_by(|&a, &b| s[b].total_cmp(&s[a]));
    // A unique solution needs a clear gap below the leading singular value.
    if s[order[1]] > s[order[0]] * (1.0 - 1e-6) {
        return Err(CalibError::Singular { method: "shah" });
    }
    let i = order[0];
    let vx: Vec<f64> = v_t.row(i).iter().copied().collect();
    let vy: Vec<f64> = u.column(i).iter().copied().collect();
    let mut rx = Matrix3::from_column_slice(&vx);
    let mut ry = Matrix3::from_column_slice(&vy);
    let dx = rx.determinant();
    let dy = ry.determinant();
    if dx == 0.0 || dy == 0.0 {
        return Err(CalibError::Singular { method: "shah" });
    }
    // The singular vectors share a sign; det must come out positive.
    rx *= dx.signum() / dx.abs().cbrt();
    ry *= dx.signum() / dy.abs().cbrt();
    let x = iso(&rx, &Vector3::zeros())?;
    let y = iso(&ry, &Vector3::zeros())?;
    let (tx, ty) = translations(pairs, &y.rotation)?;
    Ok((
        Isometry3::from_parts(Translation3::from(tx), x.rotation),
        Isometry3::from_parts(Translation3::from(ty), y.rotation),
    ))
}

/// With the rotations fixed, `R_M t_X − t_Y = R_Y t_N − t_M` in least squares over all pairs.
/// The normal matrix is `[[n·I, −Σ R_Mᵀ], [−Σ R_M, n·I]]`.
pub fn translations(
    pairs: &[Pair],
    ry: &UnitQuaternion<f64>,
) -> Result<(Vector3<f64>, Vector3<f64>), CalibError> {
    let n = pairs.len() as f64;
    let mut sum_rm = Matrix3::zeros();
    let mut top = Vector3::zeros();
    let mut bottom = Vector3::zeros();
    for p in pairs {
        let rm = rotation_of(&p.base_from_flange);
        let b =
            ry * p.tracker_from_marker.translation.vector - p.base_from_flange.translation.vector;
        sum_rm += rm;
        top += rm.transpose() * b;
        bottom -= b;
    }
    let mut a = SMatrix::<f64, 6, 6>::zeros();
    a.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(Matrix3::identity() * n));
    a.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(Matrix3::identity() * n));
    a.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(-sum_rm.transpose()));
    a.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-sum_rm));
    let rhs = SVector::<f64, 6>::new(top.x, top.y, top.z, bottom.x, bottom.y, bottom.z);
    let t = a
        .cholesky()
        .map(|c| c.solve(&rhs))
        .ok_or(CalibError::Singular {
            method: "translation",
        })?;
    Ok((
        Vector3::new(t[0], t[1], t[2]),
        Vector3::new(t[3], t[4], t[5]),
    ))
}
