//! The safety filter on every command: the coil–scalp clearance is a constraint on the next
//! command, and a command that would break it is changed as little as needed — moved back along
//! the coil's approach axis — instead of being refused and held.
//!
//! In the terms of control-barrier-function safety filters (../shared/reference/safety-filter.md):
//! the safe set is `h = d(coil, head(t + τ)) − d_req ≥ 0`, with the head predicted to the time
//! `t + τ` the command acts (tracker latency + loop + servo lag) and `d_req` the least distance
//! plus `k·σ`, the prediction's own uncertainty at that horizon (so a coasted dropout, whose
//! uncertainty grows, widens the gap). The head's motion is inside the prediction: a head moving
//! towards the coil pushes the constraint, and with it the command, back at the head's speed; a
//! head moving away releases it. The correction is the closed-form projection of a single
//! constraint with the approach axis as its direction: the least standoff `s ≥ 0` along −z of
//! the coil that restores `h ≥ 0`, found by a few secant steps on the coil's distance to the head
//! model and then checked (a scalp is not convex: beside an ear the distance need not grow
//! steadily along the axis), topped up until it holds. Links keep their own refusal rule (moving
//! a link away is not a coil motion).

use crate::config::LoopParams;
use crate::geometry::{CoilModel, HeadModel};
use mocomp_geom::nalgebra::{Isometry3, Translation3};
use mocomp_head::sampled::ClearanceMemory;

/// The clearance the coil must keep from the head model at the time a command acts, m:
/// `coil_min_distance_m` plus `safety_sigmas` times the prediction's 1σ at the coil (the position
/// uncertainty and the rotation uncertainty times the lever arm from the head marker to the coil,
/// independent, so added in quadrature).
pub fn required_clearance(p: &LoopParams, sigma_m: f64, sigma_rad: f64, lever_m: f64) -> f64 {
    let sigma = sigma_m.hypot(sigma_rad * lever_m);
    let sigma = if sigma.is_finite() { sigma } else { 0.0 };
    p.coil_min_distance_m + p.safety_sigmas * sigma
}

/// `head_from_coil` moved back by `s` along the coil's approach axis (away from the head).
pub fn backed_off(head_from_coil: &Isometry3<f64>, s: f64) -> Isometry3<f64> {
    head_from_coil * Translation3::new(0.0, 0.0, -s)
}

/// The least standoff `s ≥ 0` along the coil's approach axis that puts the coil at
/// `head_from_coil` at least `required_m` from the head model; 0 when it already is. Bounded by
/// `max_m` (a coil that cannot clear the head within it gets `max_m`).
pub fn standoff_for(
    head: &HeadModel,
    coil: &CoilModel,
    head_from_coil: &Isometry3<f64>,
    required_m: f64,
    max_m: f64,
) -> f64 {
    standoff_remembering(
        head,
        coil,
        head_from_coil,
        required_m,
        max_m,
        &mut ClearanceMemory::new(),
    )
}

/// [`standoff_for`], the same value, its first clearance sparing what `memory` (this call
/// site's, from the last cycle) shows cannot be the nearest on a scalp.
pub fn standoff_remembering(
    head: &HeadModel,
    coil: &CoilModel,
    head_from_coil: &Isometry3<f64>,
    required_m: f64,
    max_m: f64,
    memory: &mut ClearanceMemory,
) -> f64 {
    let gap = |s: f64| coil.distance(head, &backed_off(head_from_coil, s)) - required_m;
    // Most commands are clear: the bounded distance says so without the exact solve.
    let g0 = coil.distance_below_remembering(head, head_from_coil, required_m, memory) - required_m;
    if g0 >= 0.0 || g0.is_nan() {
        // Clear, or not a number (a non-finite pose is the goal check's to refuse).
        return 0.0;
    }
    // Secant steps from s = −gap (exact when the axis is the surface normal); the distance grows
    // monotonically while backing off an approach axis that points into the head.
    let (mut s0, mut g_0) = (0.0, g0);
    let mut s1 = (-g0).min(max_m);
    for _ in 0..6 {
        let g1 = gap(s1);
        if (0.0..1e-5).contains(&g1) {
            break;
        }
        let slope = (g1 - g_0) / (s1 - s0);
        let next = if slope > 0.1 {
            s1 - g1 / slope
        } else {
            s1 - g1
        };
        (s0, g_0) = (s1, g1);
        s1 = next.clamp(0.0, max_m);
        if (s1 - s0).abs() < 1e-7 {
            break;
        }
    }
    // Never less than needed, on any head: a standoff short of the requirement gets its
    // shortfall added and is checked again. The distance grows at most as fast as the coil backs
    // off, so each top-up stays at or below the least standoff; on a convex head one is enough,
    // beside an ear (where the distance along the axis need not grow steadily) a few are.
    for _ in 0..MAX_TOP_UPS {
        let g1 = gap(s1);
        // Clear (or not a number: the goal check's to refuse), or as far as it may go.
        if g1 >= 0.0 || g1.is_nan() || s1 >= max_m {
            break;
        }
        s1 = (s1 - g1).min(max_m);
    }
    s1
}

/// How often [`standoff_for`] tops a short standoff up. Still short after them only where
/// backing off along the axis barely moves the coil away (an axis grazing the scalp); the goal
/// check and the clearance the loop records see that.
const MAX_TOP_UPS: usize = 8;

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::geometry::fixtures::{coil, head};
    use mocomp_geom::nalgebra::{UnitQuaternion, Vector3};

    /// The coil on top of the head, `gap` above the scalp, facing down, tilted by `tilt` rad.
    fn on_top(gap: f64, tilt: f64) -> Isometry3<f64> {
        let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
        let tilt = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt);
        Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.11 + gap), tilt * down)
    }

    #[test]
    fn a_clear_coil_needs_no_standoff() {
        let p = LoopParams::default();
        assert_eq!(
            standoff_for(&head(), &coil(), &on_top(0.003, 0.0), 0.002, 0.1),
            0.0
        );
        assert_eq!(required_clearance(&p, 0.0, 0.0, 0.1), p.coil_min_distance_m);
    }

    #[test]
    fn the_standoff_is_the_least_that_clears_the_head() {
        // Seeded poses: inside, touching, tilted; the result clears by the requirement and a
        // standoff 0.2 mm shorter does not.
        let mut x = 11u64;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..300 {
            let gap = -0.01 + 0.02 * next();
            let tilt = 0.5 * (next() - 0.5);
            let required = 0.005 * next();
            let pose = on_top(gap, tilt);
            let s = standoff_for(&head(), &coil(), &pose, required, 0.1);
            let d = coil().distance(&head(), &backed_off(&pose, s));
            assert!(
                d >= required - 1e-9,
                "gap {gap} tilt {tilt}: {d} < {required}"
            );
            if s > 2e-4 {
                let shorter = coil().distance(&head(), &backed_off(&pose, s - 2e-4));
                assert!(shorter < required, "not the least: {s}");
            }
        }
    }

    #[test]
    fn the_standoff_is_bounded() {
        let deep = on_top(-0.05, 0.0);
        assert_eq!(standoff_for(&head(), &coil(), &deep, 0.0, 0.01), 0.01);
    }

    #[test]
    fn the_uncertainty_widens_the_required_clearance() {
        let p = LoopParams::default();
        let still = required_clearance(&p, 1e-4, 1e-3, 0.113);
        let coasting = required_clearance(&p, 2e-3, 1e-2, 0.113);
        assert!(coasting > still + 0.004, "{still} {coasting}");
        assert!(required_clearance(&p, f64::INFINITY, 0.0, 0.1).is_finite());
    }
}
