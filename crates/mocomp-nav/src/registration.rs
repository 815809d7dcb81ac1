//! The whole patient-to-image registration: the image's landmarks put on the scalp they were
//! placed on, paired with the touched ones, fitted (Kabsch) as a start, then the landmarks and
//! the swept points solved together as one weighted problem ([`crate::solve`]), with what the
//! result is worth: the pose's covariance, each landmark's error and its consistency with the
//! rest (a chi-square test of its residual against the spread the noise model and the fit
//! leave it), the landmarks' FRE (the RMS of the same errors), and the swept points' fit.
//!
//! The error at a target is a bound, not a guess: the radius that holds the registration's error
//! there with probability [`CONFIDENCE`], from the pose's covariance carried to that point
//! ([`Registration::error_bound_at`]).

use crate::NavError;
use crate::bound::{chi2_quantile, norm_quantile};
use crate::landmarks::{Landmark, register_landmarks};
use crate::noise::NoiseModel;
use crate::scalp::Scalp;
use crate::solve::{GATE_SIGMAS, Pair, point_jacobian, solve, surface_row};
use mocomp_geom::nalgebra::{
    DMatrix, DVector, Isometry3, Matrix3, Matrix6, Point3, Vector3, Vector6,
};

/// The probability the stated error bound holds.
pub const CONFIDENCE: f64 = 0.95;
/// Each consistency test refuses a correct registration this rarely (split over the landmarks
/// for the per-landmark tests).
pub const FALSE_REFUSAL: f64 = 0.001;
/// An image landmark farther than this from the scalp is not a scalp landmark (a wrong frame or
/// unit, not a placement by eye), m.
pub const MAX_IMAGE_OFFSET_M: f64 = 0.01;
/// A touched landmark farther from the skin than [`GATE_SIGMAS`] of its spread and this was not
/// touched on the skin, m.
const OFF_SKIN_SLACK_M: f64 = 1e-3;

/// An image landmark on the model's scalp.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageLandmark {
    /// Its name.
    pub name: String,
    /// On the scalp, m.
    pub point: Point3<f64>,
    /// The scalp's outward normal there.
    pub normal: Vector3<f64>,
    /// How far the given landmark was from the scalp (positive outside), m: it was put on the
    /// scalp, since a touch is on the skin.
    pub offset_m: f64,
}

/// The image's `landmarks` put on `scalp` (the nearest point), each within
/// [`MAX_IMAGE_OFFSET_M`] of it and not on a scan's cut.
pub fn on_scalp(scalp: &Scalp<'_>, landmarks: &[Landmark]) -> Result<Vec<ImageLandmark>, NavError> {
    landmarks
        .iter()
        .map(|l| {
            if !l.point.coords.iter().all(|x| x.is_finite()) {
                return Err(NavError::LandmarkNotFinite {
                    name: l.name.clone(),
                });
            }
            let s = scalp.nearest(&l.point);
            if s.signed_distance.abs() > MAX_IMAGE_OFFSET_M {
                return Err(NavError::LandmarkOffScalp {
                    name: l.name.clone(),
                    distance_m: s.signed_distance,
                    limit_m: MAX_IMAGE_OFFSET_M,
                });
            }
            if scalp.on_cut(&s.point) {
                return Err(NavError::LandmarkOnCut {
                    name: l.name.clone(),
                });
            }
            Ok(ImageLandmark {
                name: l.name.clone(),
                point: s.point,
                normal: s.normal.into_inner(),
                offset_m: s.signed_distance,
            })
        })
        .collect()
}

/// One landmark in the registration.
#[derive(Debug, Clone, PartialEq)]
pub struct LandmarkFit {
    /// Its name, as the image has it.
    pub name: String,
    /// In the image, on the scalp, m.
    pub image: Point3<f64>,
    /// How far the image's landmark was off the scalp before it was put on it, m.
    pub image_offset_m: f64,
    /// The scalp's outward normal at it.
    pub normal: Vector3<f64>,
    /// As touched, head marker frame, m.
    pub touched: Point3<f64>,
    /// The distance between the touch carried into the image and the image's landmark, m.
    pub error_m: f64,
    /// The touch's distance from the scalp (less the skin's expected give; positive outside), m.
    pub skin_m: f64,
    /// Beyond this from the scalp it was not touched on the skin, m.
    pub skin_limit_m: f64,
    /// Its residual's chi-square against the spread the noise and the fit leave it.
    pub chi2: f64,
    /// That test's degrees of freedom.
    pub dof: usize,
    /// The chi-square above which it disagrees.
    pub chi2_limit: f64,
}

impl LandmarkFit {
    /// The landmark as the image and the touch pair it.
    pub fn pair(&self) -> Pair {
        Pair {
            name: self.name.clone(),
            image: self.image,
            normal: self.normal,
            touched: self.touched,
        }
    }
}

/// How the swept points fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceFit {
    /// Points used.
    pub used: usize,
    /// Points left out as off the skin.
    pub off_skin: usize,
    /// Points left out as on a scan's cut.
    pub on_cut: usize,
    /// The used points' RMS distance across the skin (less the expected give), m.
    pub rms_m: f64,
    /// What the noise model expects of it, m.
    pub expected_rms_m: f64,
}

/// A chi-square test's outcome.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Chi2 {
    /// The statistic.
    pub value: f64,
    /// Degrees of freedom.
    pub dof: usize,
    /// The value above which it fails.
    pub limit: f64,
}

impl Chi2 {
    /// Whether it passed.
    pub fn passed(&self) -> bool {
        self.value <= self.limit
    }
}

/// A registration and what it is worth.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// The head marker's frame to the image's, m.
    pub image_from_marker: Isometry3<f64>,
    /// The covariance of a left perturbation of it (rotation, rad; translation, m) in the image's
    /// frame, about the image's origin.
    pub covariance: Matrix6<f64>,
    /// Each landmark used.
    pub landmarks: Vec<LandmarkFit>,
    /// The landmarks' FRE: the RMS of their errors, m.
    pub fre_m: f64,
    /// All the landmarks' residuals together against their spread.
    pub landmark_test: Chi2,
    /// The swept points (`None`: the landmarks alone).
    pub surface: Option<SurfaceFit>,
    /// The sweep's first and second halves (in the order swept) registered apart: how far apart
    /// they put the head against what their uncertainty allows, and the largest distance
    /// between where they put the landmarks (m). A head marker that moved on the head during the
    /// sweep shows here. `None` without enough sweep to halve.
    pub halves: Option<(Chi2, f64)>,
    /// The noise it was weighed by.
    pub noise: NoiseModel,
}

impl Registration {
    /// The covariance of the registration's error at `p` (image frame), m².
    pub fn error_covariance_at(&self, p: &Point3<f64>) -> Matrix3<f64> {
        error_covariance_at(&self.covariance, p)
    }

    /// The radius that holds the registration's error at `p` (image frame) with probability
    /// [`CONFIDENCE`], m.
    pub fn error_bound_at(&self, p: &Point3<f64>) -> f64 {
        norm_quantile(&self.error_covariance_at(p), CONFIDENCE)
    }
}

/// The covariance at `p` (image frame) of the error a pose `covariance` (left perturbation in
/// that frame) leaves, m².
pub fn error_covariance_at(covariance: &Matrix6<f64>, p: &Point3<f64>) -> Matrix3<f64> {
    let j = point_jacobian(p);
    j * covariance * j.transpose()
}

/// Registers the `touched` landmarks (head marker frame) to the `image` ones (image frame, put on
/// the scalp), together with the `swept` points (head marker frame; none: the landmarks alone),
/// against `scalp`, weighed by `noise`.
pub fn register(
    scalp: &Scalp<'_>,
    image: &[Landmark],
    touched: &[Landmark],
    swept: &[Point3<f64>],
    noise: &NoiseModel,
) -> Result<Registration, NavError> {
    let image = on_scalp(scalp, image)?;
    register_checked(scalp, &image, touched, swept, noise)
}

/// [`register_on_scalp`], and the sweep's halves registered apart ([`Registration::halves`]).
pub fn register_checked(
    scalp: &Scalp<'_>,
    image: &[ImageLandmark],
    touched: &[Landmark],
    swept: &[Point3<f64>],
    noise: &NoiseModel,
) -> Result<Registration, NavError> {
    let mut r = register_on_scalp(scalp, image, touched, swept, noise)?;
    let pairs: Vec<Pair> = r.landmarks.iter().map(LandmarkFit::pair).collect();
    r.halves = halves(scalp, &pairs, swept, noise, &r.image_from_marker)?;
    Ok(r)
}

/// [`register`] with the image's landmarks already on the scalp, without the halves' check
/// (the procedure's estimates as the sweep goes).
pub fn register_on_scalp(
    scalp: &Scalp<'_>,
    image: &[ImageLandmark],
    touched: &[Landmark],
    swept: &[Point3<f64>],
    noise: &NoiseModel,
) -> Result<Registration, NavError> {
    let as_landmarks: Vec<Landmark> = image
        .iter()
        .map(|l| Landmark::new(&l.name, l.point))
        .collect();
    let start = register_landmarks(&as_landmarks, touched)?;
    let pairs: Vec<(Pair, f64)> = image
        .iter()
        .filter_map(|i| {
            touched
                .iter()
                .find(|t| t.name.eq_ignore_ascii_case(&i.name))
                .map(|t| {
                    (
                        Pair {
                            name: i.name.clone(),
                            image: i.point,
                            normal: i.normal,
                            touched: t.point,
                        },
                        i.offset_m,
                    )
                })
        })
        .collect();
    let just_pairs: Vec<Pair> = pairs.iter().map(|(p, _)| p.clone()).collect();
    let s = solve(scalp, &just_pairs, swept, noise, &start.image_from_marker)?;
    let (landmarks, landmark_test) =
        landmark_fits(scalp, &pairs, noise, &s.image_from_marker, &s.covariance);
    let fre_m = (landmarks.iter().map(|l| l.error_m.powi(2)).sum::<f64>()
        / landmarks.len().max(1) as f64)
        .sqrt();
    let surface = (!swept.is_empty()).then(|| SurfaceFit {
        used: s.residuals.len(),
        off_skin: s.off_skin,
        on_cut: s.on_cut,
        rms_m: (s.residuals.iter().map(|r| r * r).sum::<f64>() / s.residuals.len().max(1) as f64)
            .sqrt(),
        expected_rms_m: noise.across_variance().sqrt(),
    });
    Ok(Registration {
        image_from_marker: s.image_from_marker,
        covariance: s.covariance,
        landmarks,
        fre_m,
        landmark_test,
        surface,
        halves: None,
        noise: *noise,
    })
}

/// The fewest sweep points in each half for [`Registration::halves`].
const MIN_HALF: usize = 30;

/// The sweep's halves registered apart (with the landmarks each), their poses' difference
/// against the sum of their covariances (conservative: the landmarks they share make the two
/// alike), and the largest distance at a landmark between them.
fn halves(
    scalp: &Scalp<'_>,
    pairs: &[Pair],
    swept: &[Point3<f64>],
    noise: &NoiseModel,
    from: &Isometry3<f64>,
) -> Result<Option<(Chi2, f64)>, NavError> {
    if swept.len() < 2 * MIN_HALF {
        return Ok(None);
    }
    let (first, second) = swept.split_at(swept.len() / 2);
    let a = solve(scalp, pairs, first, noise, from)?;
    let b = solve(scalp, pairs, second, noise, from)?;
    let d = b.image_from_marker * a.image_from_marker.inverse();
    let mut delta = Vector6::zeros();
    delta
        .fixed_rows_mut::<3>(0)
        .copy_from(&d.rotation.scaled_axis());
    delta
        .fixed_rows_mut::<3>(3)
        .copy_from(&d.translation.vector);
    let value = (a.covariance + b.covariance)
        .try_inverse()
        .map_or(f64::INFINITY, |w| (delta.transpose() * w * delta)[(0, 0)]);
    let apart = pairs
        .iter()
        .map(|p| (d * p.image - p.image).norm())
        .fold(0.0, f64::max);
    Ok(Some((
        Chi2 {
            value,
            dof: 6,
            limit: chi2_quantile(6, 1.0 - FALSE_REFUSAL),
        },
        apart,
    )))
}

/// Each landmark's error, its distance from the skin, and the chi-square tests of the landmarks'
/// residuals (each, and all together) against the covariance the noise and the fit leave them:
/// `C − J Σ Jᵀ`, inverted on the directions the fit did not absorb.
fn landmark_fits(
    scalp: &Scalp<'_>,
    pairs: &[(Pair, f64)],
    noise: &NoiseModel,
    pose: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
) -> (Vec<LandmarkFit>, Chi2) {
    let n = pairs.len();
    let c = noise.mean_compression_m();
    let mut r = DVector::zeros(3 * n);
    let mut cov = DMatrix::zeros(3 * n, 3 * n);
    let mut j_all = DMatrix::zeros(3 * n, 6);
    for (k, (p, _)) in pairs.iter().enumerate() {
        let q = pose * p.touched;
        r.fixed_rows_mut::<3>(3 * k)
            .copy_from(&(q - (p.image - p.normal * c)));
        cov.fixed_view_mut::<3, 3>(3 * k, 3 * k)
            .copy_from(&noise.landmark_covariance(&p.normal));
        j_all
            .fixed_view_mut::<3, 6>(3 * k, 0)
            .copy_from(&point_jacobian(&q));
    }
    let sigma = DMatrix::from_fn(6, 6, |i, j| covariance[(i, j)]);
    let residual_cov = &cov - &j_all * sigma * j_all.transpose();
    let overall = pinv_chi2(&r, &residual_cov);
    let landmark_test = Chi2 {
        value: overall.0,
        dof: overall.1,
        limit: chi2_quantile(overall.1.max(1), 1.0 - FALSE_REFUSAL),
    };
    let each_p = 1.0 - FALSE_REFUSAL / n.max(1) as f64;
    let across = noise.across_variance();
    let fits = pairs
        .iter()
        .enumerate()
        .map(|(k, (p, offset))| {
            let rk = r.fixed_rows::<3>(3 * k).into_owned();
            let ck = residual_cov.fixed_view::<3, 3>(3 * k, 3 * k).into_owned();
            let (chi2, dof) = pinv_chi2(
                &DVector::from_column_slice(rk.as_slice()),
                &DMatrix::from_column_slice(3, 3, ck.as_slice()),
            );
            let q = pose * p.touched;
            let s = scalp.nearest(&q);
            let row = surface_row(&q, &s.normal.into_inner());
            let spread = (across + (row.transpose() * covariance * row)[(0, 0)]).sqrt();
            LandmarkFit {
                name: p.name.clone(),
                image: p.image,
                image_offset_m: *offset,
                normal: p.normal,
                touched: p.touched,
                error_m: (q - p.image).norm(),
                skin_m: s.signed_distance + c,
                skin_limit_m: GATE_SIGMAS * spread + OFF_SKIN_SLACK_M,
                chi2,
                dof,
                chi2_limit: chi2_quantile(dof.max(1), each_p),
            }
        })
        .collect();
    (fits, landmark_test)
}

/// `rᵀ C⁺ r` and the rank of `C` (its eigenvalues above a thousandth of its largest): a
/// residual's Mahalanobis square over the directions it can still move in.
fn pinv_chi2(r: &DVector<f64>, c: &DMatrix<f64>) -> (f64, usize) {
    let sym = (c + c.transpose()) / 2.0;
    let e = sym.symmetric_eigen();
    let largest = e.eigenvalues.iter().copied().fold(0.0, f64::max);
    let mut chi2 = 0.0;
    let mut rank = 0;
    for (k, &l) in e.eigenvalues.iter().enumerate() {
        if l > 1e-3 * largest && l > 0.0 {
            let v = e.eigenvectors.column(k);
            chi2 += v.dot(r).powi(2) / l;
            rank += 1;
        }
    }
    (chi2, rank)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};
    use mocomp_head::Ellipsoid;
    use mocomp_testkit::SplitMix64;

    fn head() -> Ellipsoid {
        Ellipsoid::new(Isometry3::identity(), Vector3::new(0.075, 0.095, 0.11)).unwrap()
    }

    fn image(scalp: &Scalp<'_>) -> Vec<Landmark> {
        [
            ("nasion", Vector3::new(0.0, 1.0, -0.3)),
            ("lpa", Vector3::new(-1.0, -0.1, -0.35)),
            ("rpa", Vector3::new(1.0, -0.1, -0.35)),
        ]
        .iter()
        .map(|(n, d)| {
            let d = mocomp_geom::nalgebra::Unit::new_normalize(*d);
            let hit = scalp
                .shape
                .ray_hit(&(Point3::origin() + d.into_inner() * 0.3), &-d, 0.3)
                .unwrap();
            Landmark::new(n, hit.point)
        })
        .collect()
    }

    /// Landmarks alone, touched with isotropic noise: the information matrix's covariance gives
    /// Fitzpatrick, West and Maurer's TRE for a rigid fit on three fiducials (the classic
    /// prediction), and 2,000 seeded fits scatter as it says.
    #[test]
    fn landmarks_alone_scatter_as_their_covariance_says() {
        let shape = head();
        let scalp = Scalp::whole(&shape);
        let image = image(&scalp);
        // Isotropic: no compression or model error across the skin, 1 mm per axis everywhere.
        let noise = NoiseModel {
            touch_sigma_m: 0.0,
            image_landmark_sigma_m: 0.0,
            tracker_sigma_m: 1e-3,
            skin_compression_m: 0.0,
            model_sigma_m: 0.0,
            model_offset_m: 0.0,
            ..NoiseModel::default()
        };
        let truth = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.9),
            UnitQuaternion::from_euler_angles(0.3, -0.5, 1.2),
        );
        let targets = [
            Point3::new(-0.05, 0.05, 0.07),
            Point3::new(0.0, -0.02, 0.02),
        ];
        let mut rng = SplitMix64(5);
        let mut sq = [0.0; 2];
        let mut predicted = [0.0; 2];
        let trials = 2000;
        for _ in 0..trials {
            let touched: Vec<Landmark> = image
                .iter()
                .map(|l| {
                    let e = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * 1e-3;
                    Landmark::new(&l.name, truth.inverse() * (l.point + e))
                })
                .collect();
            let r = register(&scalp, &image, &touched, &[], &noise).unwrap();
            for (k, t) in targets.iter().enumerate() {
                let e = r.image_from_marker * (truth.inverse() * t) - t;
                sq[k] += e.norm_squared();
                predicted[k] = r.error_covariance_at(t).trace();
            }
        }
        for k in 0..2 {
            let measured = (sq[k] / trials as f64).sqrt();
            let said = predicted[k].sqrt();
            assert!(
                (measured / said - 1.0).abs() < 0.05,
                "{k}: {measured} {said}"
            );
            // Fitzpatrick's TRE² = FLE²/N (1 + ⅓ Σ dₖ²/fₖ²), FLE² = 3 mm².
            let fitz = fitzpatrick(&image, 3e-6, &targets[k]);
            assert!((said / fitz - 1.0).abs() < 0.01, "{said} {fitz}");
        }
    }

    fn fitzpatrick(image: &[Landmark], fle2: f64, t: &Point3<f64>) -> f64 {
        let n = image.len() as f64;
        let c: Vector3<f64> = image.iter().map(|l| l.point.coords).sum::<Vector3<f64>>() / n;
        let s: Matrix3<f64> = image
            .iter()
            .map(|l| (l.point.coords - c) * (l.point.coords - c).transpose())
            .sum();
        let axes = s.symmetric_eigen().eigenvectors;
        let r = t.coords - c;
        let mut sum = 0.0;
        for k in 0..3 {
            let e = axes.column(k);
            let off = |v: &Vector3<f64>| v.norm_squared() - v.dot(&e).powi(2);
            let f2 = image
                .iter()
                .map(|l| off(&(l.point.coords - c)))
                .sum::<f64>()
                / n;
            sum += off(&r) / f2;
        }
        (fle2 / n * (1.0 + sum / 3.0)).sqrt()
    }

    #[test]
    fn an_image_landmark_off_the_scalp_is_put_on_it_and_one_far_off_is_refused() {
        let shape = head();
        let scalp = Scalp::whole(&shape);
        let mut marks = image(&scalp);
        let nasion = marks[0].point;
        let normal = scalp.nearest(&nasion).normal.into_inner();
        marks[0].point = nasion + normal * 0.003;
        let on = on_scalp(&scalp, &marks).unwrap();
        assert!((on[0].point - nasion).norm() < 2e-4, "{:?}", on[0]);
        assert!((on[0].offset_m - 0.003).abs() < 2e-4);
        marks[0].point = nasion + normal * 0.02;
        let e = on_scalp(&scalp, &marks).unwrap_err();
        assert!(
            matches!(e, NavError::LandmarkOffScalp { ref name, .. } if name == "nasion"),
            "{e}"
        );
    }
}
