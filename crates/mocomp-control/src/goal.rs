//! The one validity check of a coil goal `head_from_coil`, used wherever a goal is accepted: the
//! loop (which holds on an invalid goal), the planner (which approaches along the goal's axis) and
//! `teach-goal` (which refuses to store one). Before, each wrote its own, with different
//! boundaries: the loop checked the coil's centre only, teach-goal refused an axis tangent to the
//! head while the planner accepted it.
//!
//! A goal is valid when
//! - the whole coil model (its face's and back's centres and rims) keeps at least
//!   `min_distance_m` from the head model, and
//! - its approach axis (+z of the coil) points into the head: a step forward along it brings the
//!   coil's face closer to the head than a step back does. An axis tangent to the surface is
//!   refused;
//! - on a scalp segmented from a scan that ends inside the head, the whole coil keeps
//!   [`SCAN_CUT_KEEP_M`] from each patch of the scan's faces the head reaches: there the model is
//!   the scan's flat face, not the patient (an ear, the brow or the neck goes on beyond it), so
//!   nothing it says about clearance holds.

use crate::geometry::{CoilModel, HeadModel};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};

/// Why a goal is refused.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum GoalError {
    /// The coil model comes closer to the head model than allowed (its nearest distance, m;
    /// negative: inside).
    #[error("the coil comes {:.1} mm {} the head model (the least allowed: {min_m} m)",
        .distance_m.abs() * 1e3, if *.distance_m < 0.0 { "inside" } else { "from" })]
    InsideHead {
        /// The coil's nearest distance to the head, m.
        distance_m: f64,
        /// The least allowed, m.
        min_m: f64,
    },
    /// The approach axis (+z of the coil) does not point into the head.
    #[error("the coil's approach axis (+z) does not point into the head")]
    AxisOutward,
    /// The goal is not a finite transform.
    #[error("the goal is not finite")]
    NotFinite,
    /// The coil comes near where the scan ends inside the head.
    #[error(
        "the coil comes within {:.1} mm of where the scan ends inside the head at its {side} \
         face, where the model is the scan's flat face and not the patient (at least {:.0} mm \
         allowed: choose a goal farther from it, or a scan that holds the head there)",
        .distance_m * 1e3, SCAN_CUT_KEEP_M * 1e3
    )]
    NearScanEdge {
        /// Which face (`left`, `anterior`, `inferior`, …).
        side: &'static str,
        /// The coil's least distance to the patch of that face the head reaches, m.
        distance_m: f64,
    },
}

/// How far the whole coil must keep from where the scan ends inside the head, m: about as far as
/// an ear stands out of the head beyond a cut through it.
pub const SCAN_CUT_KEEP_M: f64 = 0.02;

/// How far back along the axis the axis rule looks, m.
const AXIS_STEP_M: f64 = 1e-3;

/// Whether the goal's approach axis points into the head: a step forward along it brings the
/// coil's face strictly closer to the head's surface than a step back (the sign of the distance's
/// derivative along the axis; zero, a tangent axis, is not "into").
pub fn axis_points_into_head(head: &HeadModel, head_from_coil: &Isometry3<f64>) -> bool {
    let face = Point3::from(head_from_coil.translation.vector);
    let step = head_from_coil.rotation * Vector3::z() * AXIS_STEP_M;
    head.distance(&(face + step)) < head.distance(&(face - step))
}

/// Checks a goal; returns the coil's nearest distance to the head (m) when it is valid.
pub fn check_goal(
    head: &HeadModel,
    coil: &CoilModel,
    head_from_coil: &Isometry3<f64>,
    min_distance_m: f64,
) -> Result<f64, GoalError> {
    let t = head_from_coil.translation.vector;
    let q = head_from_coil.rotation.coords;
    if !(t.iter().chain(q.iter()).all(|x| x.is_finite())) {
        return Err(GoalError::NotFinite);
    }
    let distance_m = coil.distance(head, head_from_coil);
    if distance_m < min_distance_m {
        return Err(GoalError::InsideHead {
            distance_m,
            min_m: min_distance_m,
        });
    }
    if !axis_points_into_head(head, head_from_coil) {
        return Err(GoalError::AxisOutward);
    }
    near_scan_edge(head, coil, head_from_coil)?;
    Ok(distance_m)
}

/// The scan-edge rule: the whole coil keeps [`SCAN_CUT_KEEP_M`] from every patch where the scan
/// ends inside the head.
fn near_scan_edge(
    head: &HeadModel,
    coil: &CoilModel,
    head_from_coil: &Isometry3<f64>,
) -> Result<(), GoalError> {
    let cuts = head.scan_cuts();
    if cuts.is_empty() {
        return Ok(());
    }
    // Not a solid: as if touching, so the goal is refused.
    let solid = coil.solid().ok();
    for cut in cuts {
        let distance_m = solid
            .as_ref()
            .map_or(0.0, |s| cut.coil_distance(head_from_coil, s));
        if distance_m < SCAN_CUT_KEEP_M {
            return Err(GoalError::NearScanEdge {
                side: cut.side,
                distance_m,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::geometry::fixtures::{coil, head};
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};
    use std::f64::consts::{FRAC_PI_2, PI};

    /// On top of the head at `height` m, turned `tilt` rad about x from facing straight down.
    fn on_top(height: f64, tilt: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, height),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI + tilt),
        )
    }

    #[test]
    fn a_coil_on_the_scalp_facing_in_is_valid_and_its_clearance_reported() {
        let d = check_goal(&head(), &coil(), &on_top(0.113, 0.0), 0.0).unwrap();
        assert!((d - 0.003).abs() < 2e-4, "{d}");
        // The least allowed distance is a boundary the goal may sit on.
        assert!(check_goal(&head(), &coil(), &on_top(0.113, 0.0), d).is_ok());
        assert!(matches!(
            check_goal(&head(), &coil(), &on_top(0.113, 0.0), d + 1e-6),
            Err(GoalError::InsideHead { .. })
        ));
    }

    #[test]
    fn a_coil_whose_centre_is_outside_but_whose_rim_is_inside_is_refused() {
        // Tilted 60°: the face centre stays 3 mm above the scalp, the rim dips into the head
        // (the old loop check, on the centre alone, let this through).
        let g = on_top(0.113, 60f64.to_radians());
        assert!(head().distance(&Point3::from(g.translation.vector)) > 0.0);
        match check_goal(&head(), &coil(), &g, 0.0) {
            Err(GoalError::InsideHead { distance_m, .. }) => assert!(distance_m < 0.0),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn an_axis_pointing_out_or_along_the_surface_is_refused() {
        // Above the head, facing up, away from it.
        let out = Isometry3::translation(0.0, 0.0, 0.2);
        assert_eq!(
            check_goal(&head(), &coil(), &out, 0.0),
            Err(GoalError::AxisOutward)
        );
        // Far above, facing sideways: tangent to the surface below.
        let side = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.3),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), FRAC_PI_2),
        );
        assert_eq!(
            check_goal(&head(), &coil(), &side, 0.0),
            Err(GoalError::AxisOutward)
        );
        assert!(!axis_points_into_head(&head(), &side));
        assert!(axis_points_into_head(&head(), &on_top(0.3, 0.0)));
    }

    #[test]
    fn a_goal_inside_the_head_and_a_broken_one_are_named() {
        let e = check_goal(&head(), &coil(), &on_top(0.05, 0.0), 0.0).unwrap_err();
        assert!(e.to_string().contains("inside the head model"), "{e}");
        let nan = Isometry3::translation(f64::NAN, 0.0, 0.1);
        assert_eq!(
            check_goal(&head(), &coil(), &nan, 0.0),
            Err(GoalError::NotFinite)
        );
    }
}
