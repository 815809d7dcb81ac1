//! What the command gives up first when the arm cannot do everything at once: the joint step
//! within the cycle's acceleration and speed limits whose coil motion is nearest the wanted one,
//! each error weighed by its effect on the dose at the target.
//!
//! Clamping each joint on its own (what the limits did) keeps every joint as near its own wish
//! as it can, which moves the coil in a direction nobody chose: on a saturated onset the lift off
//! the scalp and the tilt, which cost the dose most, grow as readily as a slide along the scalp,
//! which costs it least. Here the step is the box-constrained weighted least squares
//! `min ‖W·Jc·(v − w)‖²` over `lo ≤ v ≤ hi`, `w` the joints' wished speeds, `Jc` the Jacobian of
//! the coil's origin in the coil's own axes and `W` the dose's sensitivity to each axis
//! ([`DOSE_WEIGHTS`]). Solved exactly by a primal active set on six unknowns, without
//! allocation; where nothing saturates the step is the wish itself, unchanged.

use mocomp_geom::nalgebra::{Isometry3, Matrix3, Matrix6, Vector6};
use mocomp_kin::Arm;

/// The dose's loss per unit error along the coil's axes, % per metre (x, y, z) and % per radian
/// (about x, y, z): the sphere figures for the Magstim 70 mm figure-of-eight, target
/// 15 mm deep, which the E-field crate's tests reproduce within 10 %: lift off the scalp (z)
/// 4.3 %/mm, tilt about the casing's edge (x, y) 3.4 %/°, turn about the axis (z) 0.15 %/°.
/// Sliding along the scalp costs 0.1 %/mm for the first millimetre, but the loss grows with the
/// square of the slide (2.2 % at 5 mm), and a slide given up cycle after cycle grows: weighed at
/// 0.1 %/mm the demo's irregular trace slid the coil off by up to 15 mm (dose 36 % off at its
/// worst); at 0.3, 0.5, 1 and 2 %/mm its worst dose error was 26, 14, 13.6 and 12.4 %, and at
/// 2 %/mm the millimetres too were better than the per-joint clamp's. So the slide is weighed
/// at 2 %/mm: still half the lift's.
pub const DOSE_WEIGHTS: [f64; 6] = [
    2.0e3,
    2.0e3,
    4.3e3,
    3.4 * 180.0 / std::f64::consts::PI,
    3.4 * 180.0 / std::f64::consts::PI,
    0.15 * 180.0 / std::f64::consts::PI,
];

/// At most this many changes of the active set (each adds or drops a joint; six unknowns need
/// far fewer): a bound on the work, never reached in the tests.
const MAX_STEPS: usize = 32;

/// The quadratic form `A = Jcᵀ W² Jc` of the arm at `q` with the coil at `flange_from_coil`: the
/// weighted squared coil error of a joint-speed error is `dvᵀ A dv`. Regularised by a millionth
/// of its trace so that a singular arm still has one answer (the nearest to the wish in joint
/// space among the equally good).
pub(super) fn dose_form(
    arm: &Arm,
    q: &[f64; 6],
    flange_from_coil: &Isometry3<f64>,
) -> Matrix6<f64> {
    let base_from_flange = arm.fk_flange(q);
    let base_from_tool = arm.fk(q);
    let base_from_coil = base_from_flange * flange_from_coil;
    let j = arm.jacobian(q);
    // The tool origin's Jacobian moved to the coil's origin (v_c = v_t − r × ω), then both halves
    // turned into the coil's axes.
    let r = base_from_coil.translation.vector - base_from_tool.translation.vector;
    let coil_from_base = base_from_coil.rotation.inverse().to_rotation_matrix();
    let rt: Matrix3<f64> = *coil_from_base.matrix();
    let lin = rt * (j.fixed_view::<3, 6>(0, 0) - r.cross_matrix() * j.fixed_view::<3, 6>(3, 0));
    let ang = rt * j.fixed_view::<3, 6>(3, 0);
    let mut wj = Matrix6::zeros();
    for c in 0..6 {
        for k in 0..3 {
            wj[(k, c)] = DOSE_WEIGHTS[k] * lin[(k, c)];
            wj[(k + 3, c)] = DOSE_WEIGHTS[k + 3] * ang[(k, c)];
        }
    }
    let a = wj.transpose() * wj;
    let ridge = 1e-6 * a.trace().max(f64::MIN_POSITIVE);
    a + Matrix6::identity() * ridge
}

/// The `v` in `[lo, hi]` (each `lo ≤ hi`) that minimises `(v − w)ᵀ A (v − w)` for a symmetric
/// positive definite `a`. Starts from the per-joint clamp and never ends above its cost.
pub(super) fn nearest_in_box(
    a: &Matrix6<f64>,
    w: &[f64; 6],
    lo: &[f64; 6],
    hi: &[f64; 6],
) -> [f64; 6] {
    let w = Vector6::from_column_slice(w);
    let lo = Vector6::from_column_slice(lo);
    let hi = Vector6::from_column_slice(hi);
    // The error d = v − w is what is solved for; its box is [lo − w, hi − w].
    let (dlo, dhi) = (lo - w, hi - w);
    let mut d = Vector6::from_fn(|j, _| 0.0f64.clamp(dlo[j], dhi[j]));
    let fixed = |d: &Vector6<f64>, j: usize| d[j] <= dlo[j] || d[j] >= dhi[j];
    let mut active: [bool; 6] = std::array::from_fn(|j| fixed(&d, j));
    for _ in 0..MAX_STEPS {
        // The best d with the active joints held where they are: the free block of A d = 0.
        let mut m = *a;
        let mut rhs = Vector6::zeros();
        for j in 0..6 {
            if active[j] {
                for k in 0..6 {
                    m[(j, k)] = 0.0;
                    m[(k, j)] = 0.0;
                }
                m[(j, j)] = 1.0;
                rhs[j] = d[j];
            }
        }
        for j in (0..6).filter(|&j| !active[j]) {
            rhs[j] = -(0..6)
                .filter(|&k| active[k])
                .map(|k| a[(j, k)] * d[k])
                .sum::<f64>();
        }
        let Some(target) = m.cholesky().map(|c| c.solve(&rhs)) else {
            break;
        };
        // Go towards it as far as the box lets: the first free joint to reach a bound stops
        // the step and joins the active set.
        let mut t = 1.0;
        let mut blocking = None;
        for j in (0..6).filter(|&j| !active[j]) {
            let step = target[j] - d[j];
            let room = if step > 0.0 {
                dhi[j] - d[j]
            } else if step < 0.0 {
                dlo[j] - d[j]
            } else {
                continue;
            };
            let tj = room / step;
            if tj < t {
                t = tj.max(0.0);
                blocking = Some(j);
            }
        }
        d += (target - d) * t;
        if let Some(j) = blocking {
            d[j] = if target[j] > d[j] { dhi[j] } else { dlo[j] }.clamp(dlo[j], dhi[j]);
            active[j] = true;
            continue;
        }
        // At the free optimum: a held joint whose gradient points into the box lets go.
        let g = a * d;
        let release = (0..6)
            .filter(|&j| active[j])
            .map(|j| {
                let into_box = if d[j] <= dlo[j] && d[j] < dhi[j] {
                    -g[j]
                } else if d[j] >= dhi[j] && d[j] > dlo[j] {
                    g[j]
                } else {
                    0.0
                };
                (j, into_box)
            })
            .filter(|&(_, gain)| gain > 1e-12 * a.trace())
            .max_by(|x, y| x.1.total_cmp(&y.1));
        match release {
            Some((j, _)) => active[j] = false,
            None => break,
        }
    }
    std::array::from_fn(|j| (w[j] + d[j]).clamp(lo[j], hi[j]))
}

/// [`nearest_in_box`] for the wish `w` slowed by the largest factor in [0, 1] (to a 1/1024)
/// whose step `fits` (the coil's speed limit); `None` when even the slowest in the box does not.
pub(super) fn slowed_in_box(
    a: &Matrix6<f64>,
    w: &[f64; 6],
    lo: &[f64; 6],
    hi: &[f64; 6],
    fits: impl Fn(&[f64; 6]) -> bool,
) -> Option<[f64; 6]> {
    let at = |k: f64| nearest_in_box(a, &w.map(|x| x * k), lo, hi);
    let full = at(1.0);
    if fits(&full) {
        return Some(full);
    }
    let mut best = at(0.0);
    if !fits(&best) {
        return None;
    }
    let (mut good, mut bad) = (0.0, 1.0);
    for _ in 0..10 {
        let k = 0.5 * (good + bad);
        let v = at(k);
        if fits(&v) {
            (good, best) = (k, v);
        } else {
            bad = k;
        }
    }
    Some(best)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use proptest::prelude::*;

    fn cost(a: &Matrix6<f64>, w: &[f64; 6], v: &[f64; 6]) -> f64 {
        let d = Vector6::from_fn(|j, _| v[j] - w[j]);
        (d.transpose() * a * d)[(0, 0)]
    }

    /// A random symmetric positive definite matrix, conditioned up to about 1e4 like the dose's.
    fn spd() -> impl Strategy<Value = Matrix6<f64>> {
        (
            proptest::collection::vec(-1.0f64..1.0, 36),
            proptest::collection::vec(-2.0f64..2.0, 6),
        )
            .prop_map(|(m, scales)| {
                let b = Matrix6::from_column_slice(&m);
                let s = Matrix6::from_diagonal(&Vector6::from_fn(|j, _| 10f64.powf(scales[j])));
                let bs = s * b;
                bs.transpose() * bs + Matrix6::identity() * 1e-3
            })
    }

    fn boxed() -> impl Strategy<Value = ([f64; 6], [f64; 6], [f64; 6])> {
        (
            proptest::array::uniform6(-3.0f64..3.0),
            proptest::array::uniform6(-2.0f64..2.0),
            proptest::array::uniform6(0.0f64..2.0),
        )
            .prop_map(|(w, c, half)| {
                let lo = std::array::from_fn(|j| c[j] - half[j]);
                let hi = std::array::from_fn(|j| c[j] + half[j]);
                (w, lo, hi)
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]

        /// Inside the box, at least as good as the per-joint clamp, and optimal: no joint can
        /// move into the box and lower the cost (the KKT conditions), checked by the gradient
        /// and by small moves along every joint.
        #[test]
        fn the_step_is_the_box_s_best(a in spd(), (w, lo, hi) in boxed()) {
            let v = nearest_in_box(&a, &w, &lo, &hi);
            for j in 0..6 {
                prop_assert!(v[j] >= lo[j] && v[j] <= hi[j], "joint {j} {} outside [{}, {}]", v[j], lo[j], hi[j]);
            }
            let clamped: [f64; 6] = std::array::from_fn(|j| w[j].clamp(lo[j], hi[j]));
            let c = cost(&a, &w, &v);
            let scale = 1e-9 * (1.0 + cost(&a, &w, &clamped));
            prop_assert!(c <= cost(&a, &w, &clamped) + scale, "{c} above the clamp's {}", cost(&a, &w, &clamped));
            let g = a * Vector6::from_fn(|j, _| v[j] - w[j]);
            let gscale = 1e-7 * (1.0 + g.norm() + a.norm());
            for j in 0..6 {
                let at_lo = v[j] <= lo[j] + 1e-12;
                let at_hi = v[j] >= hi[j] - 1e-12;
                if !at_lo && !at_hi {
                    prop_assert!(g[j].abs() <= gscale * (1.0 + (hi[j] - lo[j])), "free joint {j} gradient {}", g[j]);
                } else if at_lo && !at_hi {
                    prop_assert!(g[j] >= -gscale, "joint {j} at its low bound could go up: {}", g[j]);
                } else if at_hi && !at_lo {
                    prop_assert!(g[j] <= gscale, "joint {j} at its high bound could go down: {}", g[j]);
                }
            }
        }

        /// Slowed for a speed limit: in the box, within the limit, and not needlessly slow.
        #[test]
        fn a_slowed_step_is_in_the_box_and_fits(a in spd(), (w, lo, hi) in boxed(), limit in 0.1f64..3.0) {
            let speed = |v: &[f64; 6]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
            match slowed_in_box(&a, &w, &lo, &hi, |v| speed(v) <= limit) {
                Some(v) => {
                    prop_assert!(speed(&v) <= limit);
                    for j in 0..6 {
                        prop_assert!(v[j] >= lo[j] && v[j] <= hi[j]);
                    }
                    let full = nearest_in_box(&a, &w, &lo, &hi);
                    if speed(&full) <= limit {
                        prop_assert_eq!(v, full);
                    }
                }
                None => prop_assert!(speed(&nearest_in_box(&a, &[0.0; 6], &lo, &hi)) > limit),
            }
        }

        /// A wish the box holds is granted as it is.
        #[test]
        fn a_wish_inside_the_box_is_the_step(a in spd(), w in proptest::array::uniform6(-1.0f64..1.0)) {
            let lo = [-2.0; 6];
            let hi = [2.0; 6];
            let v = nearest_in_box(&a, &w, &lo, &hi);
            for j in 0..6 {
                prop_assert!((v[j] - w[j]).abs() < 1e-12);
            }
        }
    }

    /// With a diagonal form the joints do not interact: the per-joint clamp is the answer.
    #[test]
    fn a_diagonal_form_is_the_per_joint_clamp() {
        let a = Matrix6::from_diagonal(&Vector6::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0));
        let w = [3.0, -3.0, 0.5, 1.5, -0.2, 0.0];
        let lo = [-1.0, -1.0, -1.0, 0.0, 0.0, -1.0];
        let hi = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0];
        let v = nearest_in_box(&a, &w, &lo, &hi);
        let clamped: [f64; 6] = std::array::from_fn(|j| w[j].clamp(lo[j], hi[j]));
        for j in 0..6 {
            assert!(
                (v[j] - clamped[j]).abs() < 1e-12,
                "{v:?} against {clamped:?}"
            );
        }
    }

    /// On a UR3e, a wish (lift, tilt and some slide) each joint may reach only half of: the
    /// weighted step loses clearly less dose than the per-joint clamp.
    #[test]
    fn on_an_arm_the_lift_and_tilt_go_before_the_slide() {
        use mocomp_kin::Model;
        let arm = Arm::new(Model::Ur3e);
        let q = [0.3, -1.6, 1.4, -1.4, -1.57, 0.2];
        let flange_from_coil = Isometry3::translation(0.0, 0.0, 0.1);
        let a = dose_form(&arm, &q, &flange_from_coil);
        let base_from_coil = arm.fk_flange(&q) * flange_from_coil;
        let coil_from_base = base_from_coil.rotation.inverse();
        // Wish: lift the coil 0.2 m/s along its axis and tilt it 1 rad/s about its x, in joints.
        let jc = |q: &[f64; 6]| {
            let j = arm.jacobian(q);
            let r = base_from_coil.translation.vector - arm.fk(q).translation.vector;
            let lin = j.fixed_view::<3, 6>(0, 0) - r.cross_matrix() * j.fixed_view::<3, 6>(3, 0);
            let ang = j.fixed_view::<3, 6>(3, 0).into_owned();
            (lin, ang)
        };
        let (lin, ang) = jc(&q);
        let mut jfull = Matrix6::zeros();
        jfull
            .fixed_view_mut::<3, 6>(0, 0)
            .copy_from(&(coil_from_base.to_rotation_matrix().matrix() * lin));
        jfull
            .fixed_view_mut::<3, 6>(3, 0)
            .copy_from(&(coil_from_base.to_rotation_matrix().matrix() * ang));
        let twist = Vector6::new(0.05, 0.0, 0.2, 1.0, 0.0, 0.0);
        let wv = jfull.lu().solve(&twist).unwrap();
        let w: [f64; 6] = std::array::from_fn(|j| wv[j]);
        // Each joint may reach only half its wish.
        let lo: [f64; 6] = std::array::from_fn(|j| if w[j] < 0.0 { w[j] / 2.0 } else { 0.0 });
        let hi: [f64; 6] = std::array::from_fn(|j| if w[j] > 0.0 { w[j] / 2.0 } else { 0.0 });
        let weighted = nearest_in_box(&a, &w, &lo, &hi);
        let clamped: [f64; 6] = std::array::from_fn(|j| w[j].clamp(lo[j], hi[j]));
        let err = |v: &[f64; 6]| jfull * Vector6::from_fn(|j, _| v[j] - w[j]);
        let (ew, ec) = (err(&weighted), err(&clamped));
        let dose = |e: &Vector6<f64>| {
            (0..6)
                .map(|k| (DOSE_WEIGHTS[k] * e[k]).powi(2))
                .sum::<f64>()
        };
        assert!(
            dose(&ew) < 0.9 * dose(&ec),
            "weighted {ew:?} clamped {ec:?}"
        );
    }
}
