//! Checks that name a degenerate or inconsistent pose set before anything is solved.
//!
//! Consistency uses the invariants of `AX = XB`: for two pairs `i`, `j` the robot's relative motion
//! `A = M_i⁻¹ M_j` and the tracker's `B = N_i⁻¹ N_j` satisfy `B = X⁻¹ A X`, so they have the same
//! rotation angle and the same translation along their screw axis, whatever X and Y are.

use crate::error::{CalibError, PairRef};
use crate::noise::NoiseModel;
use crate::pairs::Pair;
use mocomp_geom::nalgebra::{Isometry3, Matrix3, Vector3};
use mocomp_geom::rotvec_from_quat;
use mocomp_geom::units::rad_to_deg;

/// Robot poses closer than this (metres) and [`DUPLICATE_ROTATION_RAD`] are duplicates.
pub const DUPLICATE_TRANSLATION_M: f64 = 1e-4;
/// See [`DUPLICATE_TRANSLATION_M`]: 0.05°.
pub const DUPLICATE_ROTATION_RAD: f64 = 0.05 * std::f64::consts::PI / 180.0;
/// The largest relative rotation must reach this (5°).
pub const MIN_ROTATION_RAD: f64 = 5.0 * std::f64::consts::PI / 180.0;
/// Relative rotations spread less than this over a second axis count as one axis.
pub const MIN_AXIS_SPREAD: f64 = 0.05;
/// Each pair is compared with up to this many others for consistency.
const COMPARISONS_PER_PAIR: usize = 24;
/// When the median pair disagrees with more than this share of its comparisons, the set is not
/// rigid (rather than having a few outliers).
const NON_RIGID_MEDIAN_SHARE: f64 = 0.3;
/// A pair disagreeing with more than this share of its comparisons is suspect.
const SUSPECT_SHARE: f64 = 0.5;

/// What the checks found in a set that passed them.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckReport {
    /// Largest rotation of a robot pose relative to the first, degrees.
    pub max_rotation_deg: f64,
    /// Spread of the relative rotations over a second axis (√(λ2/λ1) of their scatter; 0 = one
    /// axis, 1 = evenly spread).
    pub axis_spread: f64,
    /// Pairs whose motion disagrees with most others (likely outliers), by index.
    pub suspect: Vec<usize>,
}

fn finite(t: &Isometry3<f64>) -> bool {
    t.translation.vector.iter().all(|v| v.is_finite())
        && t.rotation.coords.iter().all(|v| v.is_finite())
}

/// Runs every check. Fails with the first problem found, naming the pairs involved.
pub fn check_pairs(pairs: &[Pair], noise: &NoiseModel) -> Result<CheckReport, CalibError> {
    let n = pairs.len();
    if n < 3 {
        return Err(CalibError::TooFewPairs { found: n });
    }
    for (i, p) in pairs.iter().enumerate() {
        if !finite(&p.base_from_flange) {
            return Err(CalibError::NonFinite {
                pair: p.reference(i),
                what: "base_from_flange",
            });
        }
        if !finite(&p.tracker_from_marker) {
            return Err(CalibError::NonFinite {
                pair: p.reference(i),
                what: "tracker_from_marker",
            });
        }
    }
    check_duplicates(pairs)?;
    let (max_rotation_deg, axis_spread) = check_rotations(pairs)?;
    let suspect = check_rigidity(pairs, noise)?;
    Ok(CheckReport {
        max_rotation_deg,
        axis_spread,
        suspect,
    })
}

fn check_duplicates(pairs: &[Pair]) -> Result<(), CalibError> {
    for i in 0..pairs.len() {
        let a = &pairs[i].base_from_flange;
        for (j, pj) in pairs.iter().enumerate().skip(i + 1) {
            let b = &pj.base_from_flange;
            if (a.translation.vector - b.translation.vector).norm() < DUPLICATE_TRANSLATION_M
                && a.rotation.angle_to(&b.rotation) < DUPLICATE_ROTATION_RAD
            {
                return Err(CalibError::DuplicatePoses {
                    first: pairs[i].reference(i),
                    second: pj.reference(j),
                });
            }
        }
    }
    Ok(())
}

/// Largest rotation relative to the first pose (degrees) and the axis spread.
fn check_rotations(pairs: &[Pair]) -> Result<(f64, f64), CalibError> {
    let r0 = pairs[0].base_from_flange.rotation;
    let mut scatter = Matrix3::zeros();
    let mut max_angle = 0.0f64;
    for p in &pairs[1..] {
        let w = rotvec_from_quat(&(r0.inverse() * p.base_from_flange.rotation));
        max_angle = max_angle.max(w.norm());
        scatter += w * w.transpose();
    }
    if max_angle < MIN_ROTATION_RAD {
        return Err(CalibError::RotationsTooSmall {
            max_deg: rad_to_deg(max_angle),
        });
    }
    let eig = scatter.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let l1 = eig.eigenvalues[order[0]];
    let l2 = eig.eigenvalues[order[1]].max(0.0);
    let spread = (l2 / l1).sqrt();
    if spread < MIN_AXIS_SPREAD {
        // The axis in the first flange frame, expressed in the base frame.
        let v: Vector3<f64> = r0 * eig.eigenvectors.column(order[0]).into_owned();
        return Err(CalibError::SingleAxis {
            axis: [v.x, v.y, v.z],
            spread,
        });
    }
    Ok((rad_to_deg(max_angle), spread))
}

/// The screw invariants of a relative motion: rotation angle and translation along the axis.
fn invariants(t: &Isometry3<f64>) -> (f64, f64, f64) {
    let w = rotvec_from_quat(&t.rotation);
    let angle = w.norm();
    let along = if angle > 1e-9 {
        t.translation.vector.dot(&(w / angle))
    } else {
        0.0
    };
    (angle, along, t.translation.vector.norm())
}

/// Compares each pair with up to [`COMPARISONS_PER_PAIR`] others spread over the set. Fails when
/// the set as a whole is inconsistent; returns the pairs that disagree with most others.
fn check_rigidity(pairs: &[Pair], noise: &NoiseModel) -> Result<Vec<usize>, CalibError> {
    let n = pairs.len();
    let m = COMPARISONS_PER_PAIR.min(n - 1);
    let sr = noise.residual_rotation_sigma();
    let st = noise.tracker_translation_m.hypot(noise.robot_translation_m);
    // Generous bounds: 6σ of the difference, and floors so that a modest underestimate of the
    // noise does not call a good set non-rigid.
    let tol_angle = (6.0 * std::f64::consts::SQRT_2 * sr).max(0.5f64.to_radians());
    let mut bad_share = vec![0.0; n];
    let mut inconsistent = 0usize;
    let mut total = 0usize;
    let mut worst: Option<(f64, String)> = None;
    for i in 0..n {
        let mut bad = 0usize;
        for k in 0..m {
            // Evenly spaced partners: i+1, …, covering the whole set.
            let j = (i + 1 + k * (n - 1) / m) % n;
            let a = pairs[i].base_from_flange.inverse() * pairs[j].base_from_flange;
            let b = pairs[i].tracker_from_marker.inverse() * pairs[j].tracker_from_marker;
            let (ta, da, _) = invariants(&a);
            let (tb, db, nb) = invariants(&b);
            // Axis direction noise grows as the angle shrinks; use the along-axis translation only
            // for clear rotations.
            let tol_along = if ta > 10f64.to_radians() {
                let su = std::f64::consts::SQRT_2 * sr / ta;
                (6.0 * (2.0 * st * st + (nb * su).powi(2)).sqrt()).max(0.003)
            } else {
                f64::INFINITY
            };
            let angle_excess = (ta - tb).abs() / tol_angle;
            let along_excess = (da - db).abs() / tol_along;
            total += 1;
            if angle_excess > 1.0 || along_excess > 1.0 {
                bad += 1;
                inconsistent += 1;
                let score = angle_excess.max(along_excess);
                if worst.as_ref().is_none_or(|(s, _)| score > *s) {
                    let (pi, pj): (PairRef, PairRef) =
                        (pairs[i].reference(i), pairs[j].reference(j));
                    let text = if angle_excess >= along_excess {
                        format!(
                            "between {pi} and {pj} the robot rotated {:.2}°, the tracker saw {:.2}°",
                            rad_to_deg(ta),
                            rad_to_deg(tb)
                        )
                    } else {
                        format!(
                            "between {pi} and {pj} the robot moved {:.1} mm along its rotation \
                             axis, the tracker saw {:.1} mm",
                            da.abs() * 1e3,
                            db.abs() * 1e3
                        )
                    };
                    worst = Some((score, text));
                }
            }
        }
        bad_share[i] = bad as f64 / m as f64;
    }
    let mut sorted = bad_share.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[n / 2];
    if median > NON_RIGID_MEDIAN_SHARE {
        return Err(CalibError::NonRigid {
            inconsistent,
            total,
            example: worst.map(|(_, t)| t).unwrap_or_default(),
        });
    }
    Ok((0..n).filter(|&i| bad_share[i] > SUSPECT_SHARE).collect())
}
