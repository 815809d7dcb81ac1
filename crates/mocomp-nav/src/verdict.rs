//! Whether a registration may be used, and if not, what the operator is to redo. Each check is a
//! named refusal with the figure that failed it and the limit, so the operator is told which
//! landmark to touch again or which region of the head to sweep:
//! - a landmark touched off the skin ([`Refusal::TouchedOffSkin`]);
//! - a landmark whose error the noise and the fit do not explain
//!   ([`Refusal::LandmarkDisagrees`]), or the landmarks together
//!   ([`Refusal::LandmarksDisagree`]): the touches, the image's landmarks and the scalp are not of
//!   one head as placed;
//! - the landmarks' FRE over its limit ([`Refusal::FreOverLimit`]);
//! - a sweep that does not lie on the scalp ([`Refusal::SweepOffScalp`]): another head's model;
//!   or whose halves put the head apart ([`Refusal::SweepHalvesDisagree`]): the marker slipped
//!   during the sweep;
//! - the error bound over its limit at a target ([`Refusal::TargetOverLimit`]), with the region
//!   whose sweep would lower it most.

use crate::noise::NoiseModel;
use crate::regions::{Region, SkinPoints, region_to_sweep};
use crate::registration::{CONFIDENCE, Registration};
use crate::solve::Pair;
use mocomp_geom::nalgebra::Point3;

/// A pair of landmarks whose distance differs from the image's by more than this many standard
/// deviations of that difference disagrees.
pub const PAIR_SIGMAS: f64 = 4.0;
/// A sweep whose RMS distance from the scalp exceeds its expected by this factor does not lie on
/// it.
pub const SWEEP_RMS_FACTOR: f64 = 2.0;
/// The fewest used points that make a sweep's RMS a figure to judge.
const SWEEP_RMS_MIN_POINTS: usize = 10;

/// A place where the registration's error matters.
#[derive(Debug, Clone, PartialEq)]
pub struct Target {
    /// Its name.
    pub name: String,
    /// Where, image frame, m.
    pub point: Point3<f64>,
}

/// The limits a registration is held to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// The landmarks' FRE, m.
    pub max_fre_m: f64,
    /// The error bound at each target, m.
    pub max_error_m: f64,
}

/// Why a registration may not be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refusal {
    /// A landmark's distances to the others disagree with the image's: it was touched somewhere
    /// else (in the air, on another point).
    #[error(
        "{why}: touch the {name} again, on the skin; if it disagrees again, check \
         [head.landmarks] {name} against the image"
    )]
    LandmarkMisplaced {
        /// The landmark.
        name: String,
        /// Which distance disagrees, and by how much.
        why: String,
    },
    /// A landmark was not touched on the skin.
    #[error(
        "the {name} was touched {:.1} mm {} the skin (within {:.1} mm expected): touch it again, \
         on the skin",
        .distance_m.abs() * 1e3, if *.distance_m > 0.0 { "off" } else { "inside" }, .limit_m * 1e3
    )]
    TouchedOffSkin {
        /// The landmark.
        name: String,
        /// The touch's distance from the scalp, m.
        distance_m: f64,
        /// The most expected, m.
        limit_m: f64,
    },
    /// A landmark's error is more than the noise and the fit allow.
    #[error(
        "the {name} lies {:.1} mm from the image's {name}, more than its noise allows (chi² \
         {chi2:.1} > {limit:.1}): touch it again; if it disagrees again, check [head.landmarks] \
         {name}",
        .error_m * 1e3
    )]
    LandmarkDisagrees {
        /// The landmark.
        name: String,
        /// Its error, m.
        error_m: f64,
        /// Its chi-square.
        chi2: f64,
        /// The limit.
        limit: f64,
    },
    /// The landmarks together disagree with the scalp more than their noise allows.
    #[error(
        "the landmarks disagree with the scalp more than their noise allows (chi² {chi2:.1} > \
         {limit:.1} over {dof}; FRE {:.1} mm): touch them again, and check [head.landmarks] \
         against the image",
        .fre_m * 1e3
    )]
    LandmarksDisagree {
        /// The chi-square.
        chi2: f64,
        /// Its degrees of freedom.
        dof: usize,
        /// The limit.
        limit: f64,
        /// The FRE, m.
        fre_m: f64,
    },
    /// The FRE is over its limit.
    #[error(
        "FRE {:.1} mm over its limit {:.1} mm ({worst} worst): touch the landmarks again",
        .fre_m * 1e3, .limit_m * 1e3
    )]
    FreOverLimit {
        /// The FRE, m.
        fre_m: f64,
        /// The limit, m.
        limit_m: f64,
        /// The landmark with the largest error.
        worst: String,
    },
    /// The swept points do not lie on the scalp.
    #[error(
        "the sweep lies {:.2} mm RMS off the scalp where {:.2} mm is expected: is [head] mesh \
         this patient's, and did the head marker stay put? sweep again",
        .rms_m * 1e3, .expected_m * 1e3
    )]
    SweepOffScalp {
        /// Its RMS, m.
        rms_m: f64,
        /// What the noise model expects, m.
        expected_m: f64,
    },
    /// The sweep's halves put the head apart: the marker moved on the head while sweeping.
    #[error(
        "the sweep's first and second halves put the head {:.1} mm apart (chi² {chi2:.1} > \
         {limit:.1}): did the head marker move on the head while sweeping? fix it, and register \
         again",
        .apart_m * 1e3
    )]
    SweepHalvesDisagree {
        /// How far apart, at the landmarks, m.
        apart_m: f64,
        /// The chi-square.
        chi2: f64,
        /// The limit.
        limit: f64,
    },
    /// The error bound at a target is over its limit.
    #[error(
        "the error at {target} may be up to {:.1} mm ({:.0} % bound; the limit is {:.1} mm): {}",
        .bound_m * 1e3, CONFIDENCE * 100.0, .limit_m * 1e3,
        match .region { Some(r) => format!("sweep the {r}"), None => "sweep more of the scalp, or touch the landmarks again".into() }
    )]
    TargetOverLimit {
        /// The target.
        target: String,
        /// Its error bound, m.
        bound_m: f64,
        /// The limit, m.
        limit_m: f64,
        /// The region to sweep.
        region: Option<String>,
    },
}

/// Every reason `registration` may not be used at `targets` under `limits`; `regions` (the
/// scalp's) name where to sweep when a target's bound is over, given what was `swept` (image
/// frame, with normals).
pub fn verdict(
    registration: &Registration,
    targets: &[Target],
    limits: &Limits,
    regions: &[Region],
    swept: &SkinPoints,
) -> Vec<Refusal> {
    let pairs: Vec<Pair> = registration
        .landmarks
        .iter()
        .map(crate::registration::LandmarkFit::pair)
        .collect();
    // A landmark touched elsewhere spoils the whole fit: it is what to redo, before anything the
    // fit says.
    let mut out: Vec<Refusal> = misplaced(&pairs, &registration.noise)
        .into_iter()
        .map(|(k, why)| Refusal::LandmarkMisplaced {
            name: pairs[k].name.clone(),
            why,
        })
        .collect();
    if !out.is_empty() {
        return out;
    }
    for l in &registration.landmarks {
        if l.skin_m.abs() > l.skin_limit_m {
            out.push(Refusal::TouchedOffSkin {
                name: l.name.clone(),
                distance_m: l.skin_m,
                limit_m: l.skin_limit_m,
            });
        } else if l.chi2 > l.chi2_limit {
            out.push(Refusal::LandmarkDisagrees {
                name: l.name.clone(),
                error_m: l.error_m,
                chi2: l.chi2,
                limit: l.chi2_limit,
            });
        }
    }
    let t = registration.landmark_test;
    if out.is_empty() && !t.passed() {
        out.push(Refusal::LandmarksDisagree {
            chi2: t.value,
            dof: t.dof,
            limit: t.limit,
            fre_m: registration.fre_m,
        });
    }
    if registration.fre_m > limits.max_fre_m {
        let worst = registration
            .landmarks
            .iter()
            .max_by(|a, b| a.error_m.total_cmp(&b.error_m))
            .map(|l| l.name.clone())
            .unwrap_or_default();
        out.push(Refusal::FreOverLimit {
            fre_m: registration.fre_m,
            limit_m: limits.max_fre_m,
            worst,
        });
    }
    if let Some(s) = registration.surface
        && s.used >= SWEEP_RMS_MIN_POINTS
        && s.rms_m > SWEEP_RMS_FACTOR * s.expected_rms_m
    {
        out.push(Refusal::SweepOffScalp {
            rms_m: s.rms_m,
            expected_m: s.expected_rms_m,
        });
    }
    if let Some((t, apart_m)) = registration.halves
        && !t.passed()
    {
        out.push(Refusal::SweepHalvesDisagree {
            apart_m,
            chi2: t.value,
            limit: t.limit,
        });
    }
    let over: Vec<(&Target, f64)> = targets
        .iter()
        .map(|t| (t, registration.error_bound_at(&t.point)))
        .filter(|(_, b)| *b > limits.max_error_m)
        .collect();
    if !over.is_empty() {
        let points: Vec<Point3<f64>> = targets.iter().map(|t| t.point).collect();
        let region = guidance(registration, &points, regions, swept);
        for (t, bound_m) in over {
            out.push(Refusal::TargetOverLimit {
                target: t.name.clone(),
                bound_m,
                limit_m: limits.max_error_m,
                region: region.clone(),
            });
        }
    }
    out
}

/// The region whose sweep would lower the worst bound at `targets` most, given what was
/// `swept`.
pub fn guidance(
    registration: &Registration,
    targets: &[Point3<f64>],
    regions: &[Region],
    swept: &SkinPoints,
) -> Option<String> {
    let information = registration.covariance.try_inverse()?;
    region_to_sweep(regions, &information, swept, &registration.noise, targets)
        .map(|(r, _)| r.name.to_string())
}

/// The landmarks touched somewhere else, by index, and why: every pair's distance as touched
/// against the image's, within [`PAIR_SIGMAS`] of what their noise allows (a rigid motion keeps
/// distances, so no fit is needed); a landmark in most of the pairs that disagree, or both of a
/// lone pair.
pub fn misplaced(pairs: &[Pair], noise: &NoiseModel) -> Vec<(usize, String)> {
    let n = pairs.len();
    let mut bad = vec![0usize; n];
    let mut worst = vec![(0.0f64, String::new()); n];
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = (&pairs[i], &pairs[j]);
            let e = (b.image - a.image).normalize();
            let var = (e.transpose()
                * (noise.landmark_covariance(&a.normal) + noise.landmark_covariance(&b.normal))
                * e)[(0, 0)];
            let off = (b.touched - a.touched).norm() - (b.image - a.image).norm();
            if off.abs() > PAIR_SIGMAS * var.sqrt() {
                for (k, other) in [(i, j), (j, i)] {
                    bad[k] += 1;
                    if off.abs() > worst[k].0 {
                        worst[k] = (
                            off.abs(),
                            format!(
                                "the {} is {:.1} mm {} the {} than in the image ({:.1} mm expected at most)",
                                pairs[k].name,
                                off.abs() * 1e3,
                                if off > 0.0 {
                                    "farther from"
                                } else {
                                    "nearer to"
                                },
                                pairs[other].name,
                                PAIR_SIGMAS * var.sqrt() * 1e3
                            ),
                        );
                    }
                }
            }
        }
    }
    let most = bad.iter().copied().max().unwrap_or(0);
    if most == 0 {
        return Vec::new();
    }
    (0..n)
        .filter(|&k| bad[k] == most)
        .map(|k| (k, worst[k].1.clone()))
        .collect()
}
