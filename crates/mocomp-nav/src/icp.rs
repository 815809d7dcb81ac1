//! Surface registration: points swept with the calibrated pointer over the scalp (head marker
//! frame) brought onto the scalp in the image by rigid, robust point-to-plane ICP. Rigid only:
//! no scale, no shear (InVesalius defaults to an affine ICP, which lets a registration shrink the
//! head; and applies it to positions only). Points farther than [`IcpOptions::max_distance_m`]
//! from the scalp are left out (the pointer off the head, a hair tie), and at every iteration the
//! worst share is trimmed. A sweep that leaves a motion unconstrained (all points on one side of
//! the head, or on a cylinder-like patch) is refused, naming the motion it leaves free.

use crate::NavError;
use mocomp_geom::nalgebra::{
    Isometry3, Matrix6, Point3, Translation3, UnitQuaternion, Vector3, Vector6,
};
use mocomp_head::HeadShape;

/// How an ICP runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpOptions {
    /// Points farther than this from the scalp (after the landmark registration) are left out,
    /// m (InVesalius: 20 mm).
    pub max_distance_m: f64,
    /// The share of the farthest remaining points trimmed at each iteration.
    pub trim_share: f64,
    /// The most iterations.
    pub max_iterations: usize,
    /// It stops when an iteration moves the points by less than this, m.
    pub converged_m: f64,
    /// How far a swept point is off the scalp along its normal, RMS, m: the tracker's noise and
    /// the skin giving under the tip. Weighs the sweep against the landmarks.
    pub surface_sigma_m: f64,
}

impl Default for IcpOptions {
    fn default() -> Self {
        Self {
            max_distance_m: 0.02,
            trim_share: 0.1,
            max_iterations: 60,
            converged_m: 1e-6,
            surface_sigma_m: 0.5e-3,
        }
    }
}

/// The fewest points an ICP needs after the far ones are left out.
pub const MIN_POINTS: usize = 12;
/// The least a sweep must constrain every motion, relative to the best-constrained one: below it
/// the registration can slide along that motion.
const MIN_CONSTRAINT: f64 = 5e-3;

/// The landmarks the surface registration keeps holding: a scalp swept over its cap is nearly a
/// sphere, which leaves the turn about its centre barely fixed by the sweep alone, and there the
/// landmarks fix it.
#[derive(Debug, Clone, Copy)]
pub struct Anchors<'a> {
    /// The landmarks as touched, head marker frame.
    pub marker: &'a [Point3<f64>],
    /// The same landmarks in the image, in the same order.
    pub image: &'a [Point3<f64>],
    /// Their localisation error, RMS in 3-D, m ([`crate::fle_from_fre`]).
    pub fle_m: f64,
}

/// A refined registration.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfaceRegistration {
    /// The head marker's frame to the image's, m.
    pub image_from_marker: Isometry3<f64>,
    /// The kept points' RMS distance from the scalp, m.
    pub rms_m: f64,
    /// Points used at the last iteration.
    pub kept: usize,
    /// Points left out as too far from the scalp.
    pub too_far: usize,
    /// Iterations run.
    pub iterations: usize,
}

/// Refines `initial` (`image_from_marker`, from the landmarks) so that `points` (head marker
/// frame) lie on `scalp` (image frame), with the `anchors` (the landmarks) held by their own
/// error: each residual weighed by the inverse of its variance.
pub fn refine_on_surface(
    scalp: &dyn HeadShape,
    points: &[Point3<f64>],
    initial: &Isometry3<f64>,
    anchors: Option<Anchors<'_>>,
    options: &IcpOptions,
) -> Result<SurfaceRegistration, NavError> {
    if let Some(index) = points
        .iter()
        .position(|p| !p.coords.iter().all(|x| x.is_finite()))
    {
        return Err(NavError::SurfacePointNotFinite { index });
    }
    let near: Vec<Point3<f64>> = points
        .iter()
        .filter(|p| scalp.signed_distance(&(initial * *p)).abs() <= options.max_distance_m)
        .copied()
        .collect();
    let too_far = points.len() - near.len();
    if near.len() < MIN_POINTS {
        return Err(NavError::TooFewSurfacePoints {
            near: near.len(),
            far: too_far,
            need: MIN_POINTS,
            within_m: options.max_distance_m,
        });
    }
    let mut pose = *initial;
    let keep = ((1.0 - options.trim_share) * near.len() as f64).ceil() as usize;
    let keep = keep.clamp(MIN_POINTS.min(near.len()), near.len());
    let mut iterations = 0;
    let mut rows: Vec<(f64, Vector6<f64>, f64)> = Vec::with_capacity(near.len());
    for _ in 0..options.max_iterations {
        iterations += 1;
        rows.clear();
        for p in &near {
            let q = pose * p;
            let s = scalp.nearest(&q);
            let n = s.normal.into_inner();
            let r = (q - s.point).dot(&n);
            let mut j = Vector6::zeros();
            j.fixed_rows_mut::<3>(0).copy_from(&q.coords.cross(&n));
            j.fixed_rows_mut::<3>(3).copy_from(&n);
            rows.push((r.abs(), j, r));
        }
        rows.sort_by(|a, b| a.0.total_cmp(&b.0));
        let used = &rows[..keep];
        let (mut h, mut g) = (Matrix6::zeros(), Vector6::zeros());
        for (_, j, r) in used {
            h += j * j.transpose();
            g += j * *r;
        }
        weakest(&h, &near, &pose)?;
        let w_surface = options.surface_sigma_m.powi(-2);
        h *= w_surface;
        g *= w_surface;
        if let Some(a) = anchors {
            // Per axis, a third of the 3-D variance.
            let w = 3.0 / a.fle_m.max(1e-5).powi(2);
            for (m, i) in a.marker.iter().zip(a.image) {
                let q = pose * m;
                let e = q - i;
                // δq = ω × q + v = [−[q]× | I]·δ.
                let mut j = mocomp_geom::nalgebra::Matrix3x6::zeros();
                j.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&(-q.coords.cross_matrix()));
                j.fixed_view_mut::<3, 3>(0, 3)
                    .copy_from(&mocomp_geom::nalgebra::Matrix3::identity());
                h += j.transpose() * j * w;
                g += j.transpose() * e * w;
            }
        }
        let Some(step) = h.cholesky().map(|c| c.solve(&(-g))) else {
            return Err(NavError::SurfaceUnconstrained {
                free: "every motion".into(),
            });
        };
        let rot = UnitQuaternion::from_scaled_axis(Vector3::new(step[0], step[1], step[2]));
        let update = Isometry3::from_parts(Translation3::new(step[3], step[4], step[5]), rot);
        pose = update * pose;
        // How far the update moved the points at most (the lever from the image origin).
        let lever = near
            .iter()
            .map(|p| (pose * p).coords.norm())
            .fold(0.0, f64::max);
        if step.fixed_rows::<3>(3).norm() + step.fixed_rows::<3>(0).norm() * lever
            < options.converged_m
        {
            break;
        }
    }
    let mut d: Vec<f64> = near
        .iter()
        .map(|p| scalp.signed_distance(&(pose * p)).abs())
        .collect();
    d.sort_by(f64::total_cmp);
    let kept = &d[..keep];
    Ok(SurfaceRegistration {
        image_from_marker: pose,
        rms_m: (kept.iter().map(|x| x * x).sum::<f64>() / kept.len() as f64).sqrt(),
        kept: keep,
        too_far,
        iterations,
    })
}

/// Refuses a sweep that leaves a motion free: the point-to-plane normal matrix's weakest
/// direction, scaled so rotations and translations compare (rotation by the points' radius of
/// gyration), must hold at least [`MIN_CONSTRAINT`] of its strongest.
fn weakest(
    h: &Matrix6<f64>,
    points: &[Point3<f64>],
    pose: &Isometry3<f64>,
) -> Result<(), NavError> {
    let n = points.len() as f64;
    let centre: Vector3<f64> = points
        .iter()
        .map(|p| (pose * p).coords)
        .sum::<Vector3<f64>>()
        / n;
    let radius = (points
        .iter()
        .map(|p| ((pose * p).coords - centre).norm_squared())
        .sum::<f64>()
        / n)
        .sqrt()
        .max(1e-3);
    // Rotation columns in radians times the radius: metres at the points.
    let mut scale = Matrix6::identity();
    for k in 0..3 {
        scale[(k, k)] = 1.0 / radius;
    }
    let hs = scale * h * scale;
    let eig = hs.symmetric_eigen();
    let (mut lo, mut hi) = (0, 0);
    for k in 0..6 {
        if eig.eigenvalues[k] < eig.eigenvalues[lo] {
            lo = k;
        }
        if eig.eigenvalues[k] > eig.eigenvalues[hi] {
            hi = k;
        }
    }
    if eig.eigenvalues[lo] >= MIN_CONSTRAINT * eig.eigenvalues[hi] {
        return Ok(());
    }
    let v = eig.eigenvectors.column(lo);
    let (rot, tr) = (v.fixed_rows::<3>(0).norm(), v.fixed_rows::<3>(3).norm());
    let free = if rot > tr {
        let a = v.fixed_rows::<3>(0).normalize();
        format!("a turn about ({:.2}, {:.2}, {:.2})", a.x, a.y, a.z)
    } else {
        let a = v.fixed_rows::<3>(3).normalize();
        format!("a shift along ({:.2}, {:.2}, {:.2})", a.x, a.y, a.z)
    };
    Err(NavError::SurfaceUnconstrained { free })
}
