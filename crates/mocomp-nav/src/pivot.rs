//! Pivot calibration of a tracked pointer: its tip held still on a divot while the pointer is
//! turned about it. Every sample `tracker_from_marker` puts the tip at the same point:
//! `R·tip + t = pivot`, linear in the tip (marker frame) and the pivot (tracker frame), solved
//! by least squares (as PLUS's `vtkIGSIOPivotCalibrationAlgo`). Samples whose tip lands far from
//! the pivot (a slip, a poorly seen marker) are dropped and the rest solved again; a pointer not
//! turned through [`MIN_SPREAD_RAD`] is refused, since the tip along its axis is then barely
//! fixed.

use crate::NavError;
use mocomp_geom::nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Vector3, Vector6};

/// The least orientation spread a pivoting accepts, rad (PLUS's 15°).
pub const MIN_SPREAD_RAD: f64 = 15.0 * std::f64::consts::PI / 180.0;
/// The fewest samples a pivoting needs.
pub const MIN_SAMPLES: usize = 10;
/// A sample whose tip lands more than this many times the median distance from the pivot is an
/// outlier (a median of the distances is about 1.5 σ of isotropic noise; 3 of them is about 4.6 σ).
const OUTLIER_FACTOR: f64 = 3.0;
/// Nor is any sample an outlier within this of the pivot, m (a tracker's own noise).
const OUTLIER_FLOOR_M: f64 = 0.5e-3;
/// The most the kept tips may scatter about the pivot, RMS, m (PLUS's automatic calibration aims
/// at 2 mm; optical trackers give well under 1 mm).
pub const MAX_RMS_M: f64 = 2e-3;
/// The least share of samples that must agree.
const MIN_KEPT_SHARE: f64 = 0.6;

/// A pointer's calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct PivotCalibration {
    /// The tip in the pointer marker's frame, m.
    pub tip_in_marker: Vector3<f64>,
    /// The pivot in the tracker's frame, m.
    pub pivot_in_tracker: Point3<f64>,
    /// RMS distance of the kept samples' tips from the pivot, m.
    pub rms_m: f64,
    /// The largest, m.
    pub max_m: f64,
    /// Samples used.
    pub kept: usize,
    /// Samples dropped as outliers.
    pub rejected: usize,
    /// How far the pointer turned about two independent axes (see `spread`), rad.
    pub spread_rad: f64,
}

/// Calibrates a pointer from `tracker_from_marker` samples taken while pivoting it.
pub fn calibrate_pivot(samples: &[Isometry3<f64>]) -> Result<PivotCalibration, NavError> {
    if samples.len() < MIN_SAMPLES {
        return Err(NavError::TooFewSamples {
            got: samples.len(),
            need: MIN_SAMPLES,
        });
    }
    if let Some(index) = samples.iter().position(|s| !finite(s)) {
        return Err(NavError::NotFinite { index });
    }
    let spread_rad = spread(samples);
    if spread_rad < MIN_SPREAD_RAD {
        return Err(NavError::SpreadTooSmall {
            spread_rad,
            need_rad: MIN_SPREAD_RAD,
        });
    }
    let mut keep = vec![true; samples.len()];
    let (mut tip, mut pivot) = solve(samples, &keep);
    let mut within = f64::INFINITY;
    // Drop what lands far from the pivot and solve again, until the kept set settles.
    for _ in 0..10 {
        let dist: Vec<f64> = samples
            .iter()
            .map(|s| tip_distance(s, &tip, &pivot))
            .collect();
        let mut kept: Vec<f64> = dist
            .iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(d, _)| *d)
            .collect();
        kept.sort_by(f64::total_cmp);
        let median = kept[kept.len() / 2];
        within = (OUTLIER_FACTOR * median).max(OUTLIER_FLOOR_M);
        let next: Vec<bool> = dist.iter().map(|d| *d <= within).collect();
        if next == keep {
            break;
        }
        keep = next;
        enough_agree(keep.iter().filter(|k| **k).count(), samples.len(), within)?;
        (tip, pivot) = solve(samples, &keep);
    }
    let kept_dist: Vec<f64> = samples
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(s, _)| tip_distance(s, &tip, &pivot))
        .collect();
    let kept = kept_dist.len();
    enough_agree(kept, samples.len(), within)?;
    let rms_m = (kept_dist.iter().map(|d| d * d).sum::<f64>() / kept as f64).sqrt();
    if rms_m > MAX_RMS_M {
        return Err(NavError::PivotTooPoor {
            rms_m,
            limit_m: MAX_RMS_M,
        });
    }
    Ok(PivotCalibration {
        tip_in_marker: tip,
        pivot_in_tracker: Point3::from(pivot),
        rms_m,
        max_m: kept_dist.iter().copied().fold(0.0, f64::max),
        kept,
        rejected: samples.len() - kept,
        spread_rad,
    })
}

/// Whether `kept` of `of` samples (within `within_m` of the pivot) are enough to calibrate on.
fn enough_agree(kept: usize, of: usize, within_m: f64) -> Result<(), NavError> {
    if (kept as f64) < MIN_KEPT_SHARE * of as f64 || kept < MIN_SAMPLES {
        return Err(NavError::TooManyOutliers { kept, of, within_m });
    }
    Ok(())
}

fn finite(s: &Isometry3<f64>) -> bool {
    s.translation
        .vector
        .iter()
        .chain(s.rotation.coords.iter())
        .all(|x| x.is_finite())
}

/// How far the tip of sample `s` lands from the pivot, m.
fn tip_distance(s: &Isometry3<f64>, tip: &Vector3<f64>, pivot: &Vector3<f64>) -> f64 {
    (s.rotation * tip + s.translation.vector - pivot).norm()
}

/// How far the pointer turned about two independent axes, rad: twice √2 times the RMS angle of
/// the samples' orientations (from their mean turn) about the second principal axis of turning.
/// A pivoting needs two: the points every turn about one axis leaves still form a line (that
/// axis), so a pointer only rocked in one plane, or only spun about its own length, has no single
/// tip. For tilts spread round a cone of half-angle θ this is 2θ, the cone's full opening.
fn spread(samples: &[Isometry3<f64>]) -> f64 {
    let first = samples[0].rotation;
    let turns: Vec<Vector3<f64>> = samples
        .iter()
        .map(|s| (first.inverse() * s.rotation).scaled_axis())
        .collect();
    let n = turns.len() as f64;
    let mean: Vector3<f64> = turns.iter().sum::<Vector3<f64>>() / n;
    let cov: Matrix3<f64> = turns
        .iter()
        .map(|w| (w - mean) * (w - mean).transpose())
        .sum::<Matrix3<f64>>()
        / n;
    let mut e: Vec<f64> = cov.symmetric_eigenvalues().iter().copied().collect();
    e.sort_by(|a, b| b.total_cmp(a));
    2.0 * (2.0 * e[1].max(0.0)).sqrt()
}

/// The least-squares tip and pivot over the kept samples: the normal equations of
/// `[R | −I]·[tip; pivot] = −t`, 6 × 6.
fn solve(samples: &[Isometry3<f64>], keep: &[bool]) -> (Vector3<f64>, Vector3<f64>) {
    let mut m = Matrix6::zeros();
    let mut v = Vector6::zeros();
    for (s, _) in samples.iter().zip(keep).filter(|(_, k)| **k) {
        let r: Matrix3<f64> = s.rotation.to_rotation_matrix().into_inner();
        let t = s.translation.vector;
        // AᵀA = [[I, −Rᵀ], [−R, I]]; Aᵀb = [−Rᵀt; t].
        let mut a = Matrix6::identity();
        a.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-r.transpose()));
        a.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-r));
        m += a;
        let top = -r.transpose() * t;
        for k in 0..3 {
            v[k] += top[k];
            v[k + 3] += t[k];
        }
    }
    // The spread check keeps this well conditioned; the SVD's least-squares answer either way.
    let x = m
        .svd(true, true)
        .solve(&v, 1e-12)
        .unwrap_or_else(|_| Vector6::zeros());
    (
        x.fixed_rows::<3>(0).into_owned(),
        x.fixed_rows::<3>(3).into_owned(),
    )
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic, clippy::print_stderr)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};
    use mocomp_testkit::SplitMix64;

    /// A pointer with its tip at `tip` (marker frame) pivoting on `pivot` (tracker frame),
    /// tilted up to `tilt` rad in every direction, its marker poses seen with `noise_m` of
    /// isotropic Gaussian noise on the marker's position (m, per axis).
    pub(crate) fn pivoting(
        rng: &mut SplitMix64,
        tip: Vector3<f64>,
        pivot: Vector3<f64>,
        tilt: f64,
        n: usize,
        noise_m: f64,
    ) -> Vec<Isometry3<f64>> {
        (0..n)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / n as f64 * 3.0;
                let t = tilt * (0.3 + 0.7 * rng.next_f64());
                let axis = Vector3::new(a.cos(), a.sin(), 0.0);
                let spin = rng.next_f64() * 0.5;
                let rot = UnitQuaternion::from_scaled_axis(axis * t)
                    * UnitQuaternion::from_scaled_axis(Vector3::z() * spin);
                let noise = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * noise_m;
                // R·tip + t = pivot.
                Isometry3::from_parts(Translation3::from(pivot - rot * tip + noise), rot)
            })
            .collect()
    }

    #[test]
    fn an_exact_pivoting_gives_the_tip_and_the_pivot() {
        let mut rng = SplitMix64(1);
        let tip = Vector3::new(0.01, -0.02, -0.15);
        let pivot = Vector3::new(0.1, 0.2, -1.3);
        let s = pivoting(&mut rng, tip, pivot, 0.5, 100, 0.0);
        let c = calibrate_pivot(&s).unwrap();
        assert!((c.tip_in_marker - tip).norm() < 1e-9, "{}", c.tip_in_marker);
        assert!((c.pivot_in_tracker.coords - pivot).norm() < 1e-9);
        assert!(c.rms_m < 1e-9 && c.rejected == 0 && c.kept == 100);
    }

    /// 30 seeded pivotings of 200 samples, tilted up to 30°, with 0.25 mm of tracker noise per
    /// axis: the tip is found within half a millimetre, and the reported RMS is the noise's
    /// (0.25 mm × √3 = 0.43 mm) within 15 %.
    #[test]
    fn a_noisy_pivoting_finds_the_tip_within_the_noise() {
        let tip = Vector3::new(0.005, 0.01, -0.14);
        let pivot = Vector3::new(-0.2, 0.1, -1.4);
        let mut errs = Vec::new();
        for seed in 0..30 {
            let mut rng = SplitMix64(100 + seed);
            let s = pivoting(&mut rng, tip, pivot, 30f64.to_radians(), 200, 0.25e-3);
            let c = calibrate_pivot(&s).unwrap();
            let expected = 0.25e-3 * 3f64.sqrt();
            assert!((c.rms_m / expected - 1.0).abs() < 0.15, "{}", c.rms_m);
            errs.push((c.tip_in_marker - tip).norm());
        }
        errs.sort_by(f64::total_cmp);
        eprintln!(
            "tip error over 30 pivotings: median {:.3} mm, max {:.3} mm",
            errs[15] * 1e3,
            errs[29] * 1e3
        );
        assert!(errs[29] < 0.5e-3, "{errs:?}");
    }

    #[test]
    fn slips_are_dropped_and_a_narrow_or_short_pivoting_is_refused() {
        let mut rng = SplitMix64(2);
        let tip = Vector3::new(0.0, 0.0, -0.12);
        let pivot = Vector3::new(0.0, 0.0, -1.0);
        let mut s = pivoting(&mut rng, tip, pivot, 0.5, 200, 0.25e-3);
        // Ten samples where the tip slipped 6 mm off the divot.
        for k in (0..200).step_by(20) {
            s[k].translation.vector += Vector3::new(0.006, 0.0, 0.0);
        }
        let c = calibrate_pivot(&s).unwrap();
        assert_eq!(c.rejected, 10, "{c:?}");
        assert!((c.tip_in_marker - tip).norm() < 0.5e-3, "{c:?}");
        // Tilted 5° at most: refused, named.
        let narrow = pivoting(&mut rng, tip, pivot, 5f64.to_radians(), 100, 0.0);
        match calibrate_pivot(&narrow) {
            Err(NavError::SpreadTooSmall { spread_rad, .. }) => {
                assert!(spread_rad < 10f64.to_radians())
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            calibrate_pivot(&s[..5]),
            Err(NavError::TooFewSamples { got: 5, .. })
        ));
        let mut bad = s.clone();
        bad[7].translation.vector.x = f64::NAN;
        assert_eq!(calibrate_pivot(&bad), Err(NavError::NotFinite { index: 7 }));
        // Half the samples elsewhere: no one pivot.
        let mut split = pivoting(&mut rng, tip, pivot, 0.5, 100, 0.1e-3);
        for s in split.iter_mut().skip(50) {
            s.translation.vector += Vector3::new(0.02, 0.0, 0.0);
        }
        match calibrate_pivot(&split) {
            Err(NavError::PivotTooPoor { rms_m, .. }) => assert!(rms_m > 0.008, "{rms_m}"),
            other => panic!("{other:?}"),
        }
    }
}
