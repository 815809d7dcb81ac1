//! The registration as one weighted least-squares problem: the touched landmarks and the swept
//! points together, each weighed by the noise stated for it ([`NoiseModel`]), never by what the
//! fit makes of it. Gauss–Newton on `image_from_marker`, perturbed on the left in the image's
//! frame (rotation about the image's origin, then translation); its normal matrix at the
//! solution is the information the data hold, and its inverse the pose's covariance, so a sweep
//! that leaves a motion poorly fixed (a ring, one side, a round crown) shows as a large
//! variance along that motion, which the landmarks then bound.
//!
//! The model's error is correlated along the skin: each swept point's variance carries the
//! model's part once for every point near it ([`NoiseModel::shared_weights`]), so a patch swept
//! densely weighs as one patch, and the part
//! common to the whole head ([`NoiseModel::model_offset_m`]) enters as one shared term (the
//! Sherman–Morrison form of its rank-one covariance). Points off the skin (the pointer
//! approaching, lifting off, a hair tie) are left out by a gate of [`GATE_SIGMAS`] of their own
//! predicted spread: a stated threshold, not a weight.

use crate::NavError;
use crate::noise::NoiseModel;
use crate::scalp::Scalp;
use mocomp_geom::nalgebra::{
    Isometry3, Matrix3, Matrix3x6, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6,
};

/// A swept point farther than this from the scalp under the landmarks' fit never enters, m.
pub const INITIAL_GATE_M: f64 = 0.01;
/// A swept point farther from the scalp than this many of its predicted standard deviations
/// (its own noise and the pose's uncertainty there) is not on the skin.
pub const GATE_SIGMAS: f64 = 4.0;
/// Gate, solve, gate again: at most this many rounds.
const ROUNDS: usize = 8;
/// Gauss–Newton steps per round at most.
const MAX_ITERATIONS: usize = 50;
/// A step that moves a point 100 mm from the image's origin by less than this has converged, m.
const CONVERGED_M: f64 = 1e-9;
/// The lever that turns a rotation step into a displacement for the convergence test, m.
const LEVER_M: f64 = 0.1;

/// A landmark paired between the image and the touched set.
#[derive(Debug, Clone, PartialEq)]
pub struct Pair {
    /// Its name.
    pub name: String,
    /// Where the image has it, on the model's scalp, m.
    pub image: Point3<f64>,
    /// The scalp's outward unit normal there.
    pub normal: Vector3<f64>,
    /// Where it was touched, head marker frame, m.
    pub touched: Point3<f64>,
}

/// A solved registration.
#[derive(Debug, Clone, PartialEq)]
pub struct Solution {
    /// The head marker's frame to the image's, m.
    pub image_from_marker: Isometry3<f64>,
    /// The information the data hold about a left perturbation (rotation, translation) in the
    /// image's frame, 1/rad² and 1/m².
    pub information: Matrix6<f64>,
    /// Its inverse: the pose's covariance.
    pub covariance: Matrix6<f64>,
    /// Which swept points the fit used.
    pub used: Vec<bool>,
    /// Swept points whose nearest model point lies on a scan's cut.
    pub on_cut: usize,
    /// Swept points gated out as not on the skin.
    pub off_skin: usize,
    /// Each used point's distance across the skin, less the expected compression, m.
    pub residuals: Vec<f64>,
    /// Gauss–Newton steps taken over all rounds.
    pub iterations: usize,
}

/// The Jacobian of a point `q` (image frame) under a left perturbation (ω, v): δq = ω × q + v.
pub fn point_jacobian(q: &Point3<f64>) -> Matrix3x6<f64> {
    let mut j = Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-q.coords.cross_matrix()));
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&Matrix3::identity());
    j
}

/// A swept point's row: its distance across the skin at `q` with outward normal `n`.
pub(crate) fn surface_row(q: &Point3<f64>, n: &Vector3<f64>) -> Vector6<f64> {
    let mut j = Vector6::zeros();
    j.fixed_rows_mut::<3>(0).copy_from(&q.coords.cross(n));
    j.fixed_rows_mut::<3>(3).copy_from(n);
    j
}

/// The weighted normal equations at `pose`.
struct Normal {
    h: Matrix6<f64>,
    g: Vector6<f64>,
}

fn normal_equations(
    scalp: &Scalp<'_>,
    pairs: &[(Pair, Matrix3<f64>)],
    swept: &[Point3<f64>],
    weights: &[f64],
    noise: &NoiseModel,
    pose: &Isometry3<f64>,
) -> Normal {
    let c = noise.mean_compression_m();
    let (mut h, mut g) = (Matrix6::zeros(), Vector6::zeros());
    for (p, w) in pairs {
        let q = pose * p.touched;
        let r = q - (p.image - p.normal * c);
        let j = point_jacobian(&q);
        h += j.transpose() * w * j;
        g += j.transpose() * w * r;
    }
    let (mut a, mut b, mut sum_w) = (Vector6::zeros(), 0.0, 0.0);
    for (p, &w) in swept.iter().zip(weights) {
        if w == 0.0 {
            continue;
        }
        let q = pose * p;
        let s = scalp.nearest(&q);
        let n = s.normal.into_inner();
        let r = (q - s.point).dot(&n) + c;
        let j = surface_row(&q, &n);
        h += j * j.transpose() * w;
        g += j * (w * r);
        a += j * w;
        b += w * r;
        sum_w += w;
    }
    if noise.model_offset_m > 0.0 && sum_w > 0.0 {
        let k = noise.model_offset_m.powi(-2) + sum_w;
        h -= a * a.transpose() / k;
        g -= a * (b / k);
    }
    Normal { h, g }
}

/// Solves the registration from `initial`: the `pairs` (their covariances from `noise`) and the
/// `swept` points (head marker frame) against `scalp`.
pub fn solve(
    scalp: &Scalp<'_>,
    pairs: &[Pair],
    swept: &[Point3<f64>],
    noise: &NoiseModel,
    initial: &Isometry3<f64>,
) -> Result<Solution, NavError> {
    if let Some(index) = swept
        .iter()
        .position(|p| !p.coords.iter().all(|x| x.is_finite()))
    {
        return Err(NavError::SurfacePointNotFinite { index });
    }
    let weighted: Vec<(Pair, Matrix3<f64>)> = pairs
        .iter()
        .map(|p| {
            let cov = noise.landmark_covariance(&p.normal);
            // The covariance is positive definite whenever the model validates.
            let w = cov.try_inverse().unwrap_or_else(Matrix3::zeros);
            (p.clone(), w)
        })
        .collect();
    let mut pose = *initial;
    let mut used: Vec<bool> = swept
        .iter()
        .map(|p| {
            let s = scalp.nearest(&(pose * p));
            s.signed_distance.abs() <= INITIAL_GATE_M && !scalp.on_cut(&s.point)
        })
        .collect();
    let mut iterations = 0;
    let mut covariance = Matrix6::zeros();
    let mut information = Matrix6::zeros();
    for _ in 0..ROUNDS {
        // The used points' weights (head marker frame, where they do not move); 0 for the rest.
        let kept: Vec<Point3<f64>> = swept
            .iter()
            .zip(&used)
            .filter_map(|(p, &u)| u.then_some(*p))
            .collect();
        let mut shared = noise.shared_weights(&kept).into_iter();
        let weights: Vec<f64> = used
            .iter()
            .map(|&u| if u { shared.next().unwrap_or(0.0) } else { 0.0 })
            .collect();
        for _ in 0..MAX_ITERATIONS {
            iterations += 1;
            let ne = normal_equations(scalp, &weighted, swept, &weights, noise, &pose);
            let step =
                ne.h.cholesky()
                    .map(|c| c.solve(&(-ne.g)))
                    .ok_or(NavError::Unconstrained)?;
            let rot = UnitQuaternion::from_scaled_axis(Vector3::new(step[0], step[1], step[2]));
            pose = Isometry3::from_parts(Translation3::new(step[3], step[4], step[5]), rot) * pose;
            if step.fixed_rows::<3>(3).norm() + step.fixed_rows::<3>(0).norm() * LEVER_M
                < CONVERGED_M
            {
                break;
            }
        }
        let ne = normal_equations(scalp, &weighted, swept, &weights, noise, &pose);
        information = (ne.h + ne.h.transpose()) / 2.0;
        covariance = information
            .cholesky()
            .map(|c| c.inverse())
            .ok_or(NavError::Unconstrained)?;
        let regated = gate(scalp, swept, noise, &pose, &covariance);
        if regated == used {
            break;
        }
        used = regated;
    }
    let c = noise.mean_compression_m();
    let mut residuals = Vec::new();
    let (mut on_cut, mut off_skin) = (0, 0);
    for (p, &u) in swept.iter().zip(&used) {
        let q = pose * p;
        let s = scalp.nearest(&q);
        if u {
            residuals.push((q - s.point).dot(&s.normal) + c);
        } else if scalp.on_cut(&s.point) {
            on_cut += 1;
        } else {
            off_skin += 1;
        }
    }
    Ok(Solution {
        image_from_marker: pose,
        information,
        covariance,
        used,
        on_cut,
        off_skin,
        residuals,
        iterations,
    })
}

/// Which swept points lie on the skin at `pose`: within [`GATE_SIGMAS`] of the spread their own
/// noise and the pose's `covariance` predict, and not on a scan's cut.
fn gate(
    scalp: &Scalp<'_>,
    swept: &[Point3<f64>],
    noise: &NoiseModel,
    pose: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
) -> Vec<bool> {
    let c = noise.mean_compression_m();
    let own = noise.across_variance();
    swept
        .iter()
        .map(|p| {
            let q = pose * p;
            let s = scalp.nearest(&q);
            let n = s.normal.into_inner();
            let r = (q - s.point).dot(&n) + c;
            let j = surface_row(&q, &n);
            let var = own + (j.transpose() * covariance * j)[(0, 0)];
            r.abs() <= GATE_SIGMAS * var.sqrt() && !scalp.on_cut(&s.point)
        })
        .collect()
}
