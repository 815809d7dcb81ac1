//! Weighted nonlinear least squares on SE(3) for `M_i · X = Y · N_i`.
//!
//! The residual of pair `i` is `E_i = (Y·N_i)⁻¹·M_i·X` (the marker pose the robot chain predicts,
//! seen from the measured one): its rotation vector (radians) and translation (metres), each divided
//! by the expected noise ([`NoiseModel`]). `X` and `Y` are updated by right perturbations
//! `X·exp(δX)`, `Y·exp(δY)`; with `P_i = Y⁻¹·M_i·X`,
//! `E_i(δ) ≈ E_i·exp(δX − Ad(P_i⁻¹)·δY)`, which gives the analytic 6×12 Jacobian used here.
//! Levenberg–Marquardt on the 12×12 normal equations; Huber weights make it robust to outlier pairs.

use crate::noise::NoiseModel;
use crate::pairs::Pair;
use mocomp_geom::nalgebra::{Isometry3, Matrix3, SMatrix, SVector, Translation3, Vector3};
use mocomp_geom::{quat_from_rotvec, rotvec_from_quat};

/// 12×12 matrix (information / normal equations).
pub type Mat12 = SMatrix<f64, 12, 12>;
type Vec12 = SVector<f64, 12>;

/// A pair's normalised residual norm above this gets a Huber weight below 1 (√χ²₆ at ≈ 99.7 %).
pub const HUBER_K: f64 = 4.5;
/// Median of the χ² distribution with 6 degrees of freedom.
pub const CHI2_6_MEDIAN: f64 = 5.348;
/// √ of the 99.9 % quantile of χ²₆: a pair beyond this (times the robust scale) is an outlier.
pub const OUTLIER_THRESHOLD: f64 = 4.74;

/// A pair's residual: rotation vector (rad) and translation (m) of `E_i`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Residual {
    /// Rotation vector of `E_i`, radians.
    pub rotation: Vector3<f64>,
    /// Translation of `E_i`, metres (the position error of the marker).
    pub translation: Vector3<f64>,
}

fn skew(v: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -v.z, v.y, v.z, 0.0, -v.x, -v.y, v.x, 0.0)
}

/// The residual of one pair at `x`, `y`.
pub fn residual(pair: &Pair, x: &Isometry3<f64>, y: &Isometry3<f64>) -> Residual {
    let e = pair.tracker_from_marker.inverse() * y.inverse() * pair.base_from_flange * x;
    Residual {
        rotation: rotvec_from_quat(&e.rotation),
        translation: e.translation.vector,
    }
}

/// Per-pair noise: rotation and translation standard deviations of the residual.
fn sigmas(noise: &NoiseModel, x: &Isometry3<f64>) -> (f64, f64) {
    (
        noise.residual_rotation_sigma(),
        noise.residual_translation_sigma(x.translation.vector.norm()),
    )
}

/// The normalised residual norm of one pair (√ of its χ² contribution).
pub fn normalized(r: &Residual, sr: f64, st: f64) -> f64 {
    (r.rotation.norm_squared() / (sr * sr) + r.translation.norm_squared() / (st * st)).sqrt()
}

fn cost(
    pairs: &[Pair],
    w: &[f64],
    x: &Isometry3<f64>,
    y: &Isometry3<f64>,
    sr: f64,
    st: f64,
) -> f64 {
    pairs
        .iter()
        .zip(w)
        .map(|(p, wi)| wi * normalized(&residual(p, x, y), sr, st).powi(2))
        .sum()
}

/// Normal equations `H = Σ wᵢ JᵢᵀJᵢ`, `g = Σ wᵢ Jᵢᵀ rᵢ` of the weighted problem at `x`, `y`.
pub fn normal_equations(
    pairs: &[Pair],
    w: &[f64],
    x: &Isometry3<f64>,
    y: &Isometry3<f64>,
    sr: f64,
    st: f64,
) -> (Mat12, Vec12) {
    let mut h = Mat12::zeros();
    let mut g = Vec12::zeros();
    let y_inv = y.inverse();
    for (p, wi) in pairs.iter().zip(w) {
        if *wi == 0.0 {
            continue;
        }
        let pm = y_inv * p.base_from_flange * x; // P_i = Y⁻¹ M_i X
        let e = p.tracker_from_marker.inverse() * pm;
        let phi = rotvec_from_quat(&e.rotation);
        let rt = pm.rotation.to_rotation_matrix().into_inner().transpose(); // R_Pᵀ
        let re = e.rotation.to_rotation_matrix().into_inner();
        let jr_inv = Matrix3::identity() + skew(&phi) * 0.5;
        // Rows 0–2: rotation, rows 3–5: translation; columns [δXω, δXv, δYω, δYv].
        let mut j = SMatrix::<f64, 6, 12>::zeros();
        j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(jr_inv / sr));
        j.fixed_view_mut::<3, 3>(0, 6)
            .copy_from(&(-jr_inv * rt / sr));
        j.fixed_view_mut::<3, 3>(3, 3).copy_from(&(re / st));
        j.fixed_view_mut::<3, 3>(3, 6)
            .copy_from(&(re * rt * skew(&pm.translation.vector) / st));
        j.fixed_view_mut::<3, 3>(3, 9).copy_from(&(-re * rt / st));
        let r = SVector::<f64, 6>::new(
            phi.x / sr,
            phi.y / sr,
            phi.z / sr,
            e.translation.x / st,
            e.translation.y / st,
            e.translation.z / st,
        );
        let jt = j.transpose();
        h += (jt * j) * *wi;
        g += (jt * r) * *wi;
    }
    (h, g)
}

fn retract(t: &Isometry3<f64>, d: &[f64]) -> Isometry3<f64> {
    let step = Isometry3::from_parts(
        Translation3::new(d[3], d[4], d[5]),
        quat_from_rotvec(&Vector3::new(d[0], d[1], d[2])),
    );
    t * step
}

/// Result of a refinement.
#[derive(Debug, Clone, Copy)]
pub struct Refined {
    /// `flange_from_marker`.
    pub x: Isometry3<f64>,
    /// `base_from_tracker`.
    pub y: Isometry3<f64>,
    /// LM iterations taken.
    pub iterations: usize,
}

/// Levenberg–Marquardt from `(x, y)` with fixed per-pair weights `w`.
pub fn levenberg_marquardt(
    pairs: &[Pair],
    w: &[f64],
    mut x: Isometry3<f64>,
    mut y: Isometry3<f64>,
    noise: &NoiseModel,
) -> Refined {
    let (sr, st) = sigmas(noise, &x);
    let mut current = cost(pairs, w, &x, &y, sr, st);
    let mut lambda = 1e-4;
    let mut iterations = 0;
    for _ in 0..100 {
        iterations += 1;
        let (h, g) = normal_equations(pairs, w, &x, &y, sr, st);
        let mut accepted = false;
        let mut small_step = false;
        while lambda < 1e12 {
            let mut a = h;
            for k in 0..12 {
                a[(k, k)] += lambda * h[(k, k)].max(1e-12);
            }
            let Some(ch) = a.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let d = -ch.solve(&g);
            let xn = retract(&x, &d.as_slice()[0..6]);
            let yn = retract(&y, &d.as_slice()[6..12]);
            let c = cost(pairs, w, &xn, &yn, sr, st);
            small_step = d.amax() < 1e-13;
            if c <= current {
                let gain = current - c;
                x = xn;
                y = yn;
                current = c;
                lambda = (lambda * 0.1).max(1e-12);
                accepted = true;
                small_step |= gain <= 1e-15 * (1.0 + c);
                break;
            }
            lambda *= 10.0;
            if small_step {
                break;
            }
        }
        if !accepted || small_step {
            break;
        }
    }
    Refined { x, y, iterations }
}

/// Huber weights for normalised residual norms.
pub fn huber_weights(norms: &[f64]) -> Vec<f64> {
    norms
        .iter()
        .map(|&r| if r <= HUBER_K { 1.0 } else { HUBER_K / r })
        .collect()
}

/// The robust scale of normalised residual norms: 1 when the noise model fits, larger when the
/// data are noisier than modelled (so that a mis-set model does not make every pair an outlier).
pub fn robust_scale(norms: &[f64]) -> f64 {
    if norms.is_empty() {
        return 1.0;
    }
    let mut sq: Vec<f64> = norms.iter().map(|r| r * r).collect();
    sq.sort_by(f64::total_cmp);
    (sq[sq.len() / 2] / CHI2_6_MEDIAN).sqrt().max(1.0)
}

/// Normalised residual norms of every pair.
pub fn norms(
    pairs: &[Pair],
    x: &Isometry3<f64>,
    y: &Isometry3<f64>,
    noise: &NoiseModel,
) -> Vec<f64> {
    let (sr, st) = sigmas(noise, x);
    pairs
        .iter()
        .map(|p| normalized(&residual(p, x, y), sr, st))
        .collect()
}

/// Robust refinement: plain weighted least squares, then Huber reweighting until the weights
/// settle (at most a few rounds).
pub fn refine_robust(
    pairs: &[Pair],
    x: Isometry3<f64>,
    y: Isometry3<f64>,
    noise: &NoiseModel,
) -> Refined {
    let mut w = vec![1.0; pairs.len()];
    let mut r = levenberg_marquardt(pairs, &w, x, y, noise);
    let mut total = r.iterations;
    for _ in 0..4 {
        let nw = huber_weights(&norms(pairs, &r.x, &r.y, noise));
        let change = nw
            .iter()
            .zip(&w)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        if change < 1e-3 {
            break;
        }
        w = nw;
        r = levenberg_marquardt(pairs, &w, r.x, r.y, noise);
        total += r.iterations;
    }
    r.iterations = total;
    r
}

/// The information matrix `H` (unit weights) at `x`, `y`, for uncertainty and conditioning.
pub fn information(
    pairs: &[Pair],
    x: &Isometry3<f64>,
    y: &Isometry3<f64>,
    noise: &NoiseModel,
) -> Mat12 {
    let (sr, st) = sigmas(noise, x);
    normal_equations(pairs, &vec![1.0; pairs.len()], x, y, sr, st).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_geom::nalgebra::Vector6;

    /// The analytic Jacobian against finite differences of the residual.
    #[test]
    fn jacobian_matches_finite_differences() {
        let x = Isometry3::from_parts(
            Translation3::new(0.02, -0.03, 0.1),
            quat_from_rotvec(&Vector3::new(0.3, -0.2, 0.5)),
        );
        let y = Isometry3::from_parts(
            Translation3::new(1.2, 0.4, 0.5),
            quat_from_rotvec(&Vector3::new(-1.0, 2.0, 0.3)),
        );
        let m = Isometry3::from_parts(
            Translation3::new(0.3, -0.2, 0.4),
            quat_from_rotvec(&Vector3::new(2.0, 1.0, -0.5)),
        );
        // A slightly inconsistent measurement so the residual is not zero.
        let n = (y.inverse() * m * x)
            * Isometry3::from_parts(
                Translation3::new(0.001, 0.002, -0.001),
                quat_from_rotvec(&Vector3::new(0.002, -0.001, 0.003)),
            );
        let pair = Pair::new(m, n);
        let (sr, st) = (1.0, 1.0);
        let (h, g) = normal_equations(&[pair], &[1.0], &x, &y, sr, st);
        // Recover J from H and g is not possible; instead compare g = Jᵀr with a numeric Jᵀr.
        let r0 = residual(&pair, &x, &y);
        let r0v = Vector6::new(
            r0.rotation.x,
            r0.rotation.y,
            r0.rotation.z,
            r0.translation.x,
            r0.translation.y,
            r0.translation.z,
        );
        let mut jnum = SMatrix::<f64, 6, 12>::zeros();
        let eps = 1e-7;
        for k in 0..12 {
            let mut d = [0.0; 12];
            d[k] = eps;
            let (xp, yp) = (retract(&x, &d[0..6]), retract(&y, &d[6..12]));
            let r = residual(&pair, &xp, &yp);
            let rv = Vector6::new(
                r.rotation.x,
                r.rotation.y,
                r.rotation.z,
                r.translation.x,
                r.translation.y,
                r.translation.z,
            );
            jnum.set_column(k, &((rv - r0v) / eps));
        }
        let g_num = jnum.transpose() * r0v;
        assert!((g - g_num).amax() < 1e-6, "g {g} vs {g_num}");
        let h_num = jnum.transpose() * jnum;
        assert!((h - h_num).amax() < 1e-4 * h_num.amax(), "H differs");
    }

    #[test]
    fn huber_and_scale() {
        assert_eq!(huber_weights(&[1.0, 9.0]), vec![1.0, 0.5]);
        assert_eq!(robust_scale(&[1.0, 1.0, 1.0]), 1.0);
        let s = robust_scale(&[6.0; 5]);
        assert!((s - 6.0 / CHI2_6_MEDIAN.sqrt()).abs() < 1e-12);
    }
}
