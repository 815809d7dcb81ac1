//! Closed-form inverse kinematics of the UR geometry (after Hawkins 2013, re-derived with `atan2`
//! throughout), its branch labels, and the fixed-capacity solution set.
//!
//! # Derivation (standard DH, frame 1 = base rotated by `q1`, then `Rx(π/2)`)
//! - Wrist point `p5 = p − d6·z6`. The axes 2–4 are parallel to `z1 = (sin q1, −cos q1, 0)`, and
//!   `p5 · z1 = d4`. With `r` the horizontal distance of `p5` from the base axis and
//!   `ρ = ±√(r² − d4²)`: `q1 = atan2(p5y, p5x) + atan2(d4, ρ)`. `ρ` is the signed horizontal reach
//!   of the wrist point in the arm plane; its sign is the **shoulder** branch.
//! - In frame 1 the orientation is `R16 = Rz(q234)·Ry(−q5)·Rz(q6)`, whose third row is
//!   `(sin q5 cos q6, −sin q5 sin q6, cos q5)`: `q5 = atan2(±√(..), cos q5)` (the sign is the
//!   **wrist** branch) and `q6` follows. `q234 = q2 + q3 + q4` comes from the first column of
//!   `R16 · Rz(−q6) · Ry(q5)`.
//! - Wrist 1 in the arm plane: `p4 = p5 − d5·(sin q234, −cos q234)`, a planar two-link problem:
//!   `cos q3` from the law of cosines, `q3 = atan2(±sin, cos)` (the **elbow** branch), then `q2`
//!   and `q4 = q234 − q2 − q3`.
//!
//! # Singular cases, handled on purpose
//! - **Wrist** (`sin q5 ≈ 0`, axes 4 and 6 aligned): only `q234 ± q6` is determined. The flip pair
//!   merges into one solution; `q6` keeps the hint (the current `q6`) unless that makes the wrist
//!   unreachable, in which case the nearest `q6` that works is used.
//! - **Shoulder** (`ρ ≈ 0`: the wrist point in the plane of axes 1 and 2): the two shoulder roots
//!   merge. (For the UR, "wrist centre on the base axis" is inside the `d4` cylinder and cannot be
//!   reached; the singular configuration is this plane.)
//! - **Elbow** stretched or folded (`sin q3 ≈ 0`): the elbow pair merges; rounding that puts
//!   `cos q3` a hair beyond ±1 is clamped.
//! - **Unreachable**: an error saying which constraint failed and by how much.

use crate::branch::{Branch, Elbow, Shoulder, Wrist};
use crate::error::Unreachable;
use crate::model::UrGeometry;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::units::wrap_pi;
use std::f64::consts::PI;

/// The three quantities whose signs define the branch and whose zeros are the singularities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BranchCoordinates {
    /// Signed horizontal reach of the wrist point in the arm plane, metres
    /// (`a2 cos q2 + a3 cos(q2+q3) + d5 sin(q2+q3+q4)`). Zero: shoulder singularity.
    pub rho_m: f64,
    /// `sin q3`. Zero: elbow stretched or folded.
    pub sin_q3: f64,
    /// `sin q5`. Zero: wrist singularity.
    pub sin_q5: f64,
}

impl BranchCoordinates {
    /// The coordinates of a joint configuration on a nominal geometry.
    pub fn of(g: &UrGeometry, q: &[f64; 6]) -> Self {
        let q23 = q[1] + q[2];
        let q234 = q23 + q[3];
        Self {
            rho_m: g.a2 * q[1].cos() + g.a3 * q23.cos() + g.d5 * q234.sin(),
            sin_q3: q[2].sin(),
            sin_q5: q[4].sin(),
        }
    }

    /// The branch these coordinates lie on (a zero coordinate counts as left / up / noflip).
    pub fn branch(&self) -> Branch {
        label(self.rho_m, self.sin_q3, self.sin_q5)
    }
}

#[inline]
fn label(rho: f64, s3: f64, s5: f64) -> Branch {
    let shoulder = if rho >= 0.0 {
        Shoulder::Left
    } else {
        Shoulder::Right
    };
    // In frame 1, y points up and the arm reaches along sign(ρ)·x. The elbow e = a2(c2, s2) is
    // left of (above) the shoulder→wrist vector w iff w × e > 0, and w × e = −a2·a3·sin q3 with
    // a2·a3 > 0. Seen with the arm reaching forward, "above" is w × e > 0 for ρ ≥ 0 and < 0 for
    // ρ < 0.
    let up = match shoulder {
        Shoulder::Left => s3 <= 0.0,
        Shoulder::Right => s3 >= 0.0,
    };
    Branch {
        shoulder,
        elbow: if up { Elbow::Up } else { Elbow::Down },
        wrist: if s5 >= 0.0 {
            Wrist::NoFlip
        } else {
            Wrist::Flip
        },
    }
}

/// One IK solution: joint angles (radians) and the branch it lies on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkSolution {
    /// Joint angles, radians, base to wrist 3.
    pub joints: [f64; 6],
    /// Its branch.
    pub branch: Branch,
}

/// Which singular cases the solver met (solutions merged or chosen from a continuum).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SingularCases {
    /// The shoulder roots merged (`ρ ≈ 0`).
    pub shoulder: bool,
    /// An elbow pair merged (arm fully stretched or folded).
    pub elbow: bool,
    /// The wrist is singular (`sin q5 ≈ 0`): `q6` was chosen from a continuum.
    pub wrist: bool,
}

/// Up to eight IK solutions, stored inline (no allocation).
#[derive(Debug, Clone, Copy)]
pub struct Solutions {
    items: [IkSolution; 8],
    len: usize,
    /// Singular cases met while solving.
    pub singular: SingularCases,
}

impl Solutions {
    pub(crate) fn new() -> Self {
        const EMPTY: IkSolution = IkSolution {
            joints: [0.0; 6],
            branch: Branch {
                shoulder: Shoulder::Left,
                elbow: Elbow::Up,
                wrist: Wrist::NoFlip,
            },
        };
        Self {
            items: [EMPTY; 8],
            len: 0,
            singular: SingularCases::default(),
        }
    }

    pub(crate) fn push(&mut self, s: IkSolution) {
        if self.len < self.items.len() {
            self.items[self.len] = s;
            self.len += 1;
        }
    }

    /// Keeps only the solutions for which `keep` is true.
    pub(crate) fn retain(&mut self, mut keep: impl FnMut(&mut IkSolution) -> bool) {
        let mut n = 0;
        for i in 0..self.len {
            let mut s = self.items[i];
            if keep(&mut s) {
                self.items[n] = s;
                n += 1;
            }
        }
        self.len = n;
    }

    /// The solutions as a slice.
    pub fn as_slice(&self) -> &[IkSolution] {
        &self.items[..self.len]
    }

    /// Iterates the solutions.
    pub fn iter(&self) -> std::slice::Iter<'_, IkSolution> {
        self.as_slice().iter()
    }

    /// Number of solutions.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when there is no solution.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The solution on a given branch, if any.
    pub fn on_branch(&self, branch: Branch) -> Option<&IkSolution> {
        self.iter().find(|s| s.branch == branch)
    }
}

impl<'a> IntoIterator for &'a Solutions {
    type Item = &'a IkSolution;
    type IntoIter = std::slice::Iter<'a, IkSolution>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// `|sin q5|` below which the wrist counts as singular. The merged solution sets `q5` to exactly 0
/// or π, an orientation error of at most this angle (and `d6` times it in position).
pub const WRIST_SINGULAR_EPS: f64 = 1e-10;
/// `ρ²` (m²) at or below which the two shoulder roots are merged (ρ ≤ 1e-8 m). Merging moves the
/// wrist point by less than 1e-15 m because frame 1 is re-projected after choosing `q1`.
pub const SHOULDER_MERGE_RHO2: f64 = 1e-16;
/// `ρ²` (m²) below `−this` means the wrist point is really inside the `d4` cylinder (beyond what
/// rounding explains).
pub const SHOULDER_UNREACHABLE_RHO2: f64 = 1e-14;
/// `|cos q3|` may exceed 1 by this much through rounding before the elbow counts as unreachable.
pub const ELBOW_COS_TOL: f64 = 1e-12;
/// `|sin q3|` below which the elbow pair is merged into one solution with `q3` exactly 0 or π.
/// Near a stretched or folded arm `sin q3` carries √ε ≈ 3e-8 of rounding noise; the reach depends
/// on `q3` only quadratically there, so merging moves wrist 1 by at most `a2·a3·sin²q3 / |p4|`,
/// about 1e-15 m.
pub const ELBOW_MERGE_SIN: f64 = 1e-7;
/// Solutions whose joints agree within this (radians, per joint, modulo 2π) are reported once.
pub const MERGE_TOL: f64 = 1e-9;

/// Below this `|sin q5|` the split of `q234 + q6` into its parts is determined only to about
/// `1e-16 / |sin q5|`; a reach failure by that little is repaired by moving within the split.
pub const WRIST_NEAR_SINGULAR: f64 = 1e-4;
/// Largest orientation error (radians) accepted when moving within that split.
const WRIST_SPLIT_ERROR: f64 = 1e-11;

/// How far past the reach boundaries the closed form still produces a (clamped) solution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Slack {
    /// `ρ²` (m²) may be this far below 0 (wrist point inside the `d4` cylinder).
    pub rho2: f64,
    /// `|cos q3|` may exceed 1 by this much.
    pub cos3: f64,
    /// Instead of merging a near pair of shoulder roots, emit two with `|ρ|` at least this
    /// (metres); 0 merges them.
    pub split_rho_m: f64,
    /// Instead of merging a near elbow pair, emit two with `|sin q3|` at least this; 0 merges them.
    pub split_sin3: f64,
}

/// Rounding-level slack: what the nominal geometry uses.
pub const STRICT: Slack = Slack {
    rho2: SHOULDER_UNREACHABLE_RHO2,
    cos3: ELBOW_COS_TOL,
    split_rho_m: 0.0,
    split_sin3: 0.0,
};

/// Slack for starting points of a calibrated robot, whose reach differs from the nominal one by
/// up to centimetres: the clamped closed-form answers are refined against the exact chain, which
/// decides whether they are solutions. Near-merged pairs are split into one start on each side,
/// because the calibrated arm may have two distinct solutions where the nominal one has one.
pub const CALIBRATION_START: Slack = Slack {
    rho2: 0.02,
    cos3: 0.2,
    split_rho_m: 0.05,
    split_sin3: 0.1,
};

/// Closed-form IK of the nominal geometry for `base_from_flange`. `q6_hint` is used only at a wrist
/// singularity. Solutions come out in `(−π, π]` per joint, distinct, each with its branch.
pub fn solve(
    g: &UrGeometry,
    base_from_flange: &Isometry3<f64>,
    q6_hint: f64,
) -> Result<Solutions, Unreachable> {
    solve_with(g, base_from_flange, q6_hint, &STRICT)
}

/// [`solve`] with a chosen [`Slack`].
pub fn solve_with(
    g: &UrGeometry,
    base_from_flange: &Isometry3<f64>,
    q6_hint: f64,
    slack: &Slack,
) -> Result<Solutions, Unreachable> {
    let m = base_from_flange.rotation.to_rotation_matrix();
    let m = m.matrix();
    let axes = [
        [m[(0, 0)], m[(1, 0)], m[(2, 0)]],
        [m[(0, 1)], m[(1, 1)], m[(2, 1)]],
        [m[(0, 2)], m[(1, 2)], m[(2, 2)]],
    ];
    let z6 = axes[2];
    let p = base_from_flange.translation.vector;
    let p5 = [p.x - g.d6 * z6[0], p.y - g.d6 * z6[1], p.z - g.d6 * z6[2]];

    let r2 = p5[0] * p5[0] + p5[1] * p5[1];
    let rho2 = r2 - g.d4 * g.d4;
    if rho2 < -slack.rho2 {
        return Err(Unreachable::InsideShoulderCylinder {
            distance_m: r2.sqrt(),
            radius_m: g.d4,
        });
    }
    let mut out = Solutions::new();
    let rho = if rho2 <= SHOULDER_MERGE_RHO2 {
        out.singular.shoulder = true;
        0.0
    } else {
        rho2.sqrt()
    };
    let rho = if rho < slack.split_rho_m {
        slack.split_rho_m
    } else {
        rho
    };
    let reach = ((g.a2.abs() - g.a3.abs()).abs(), g.a2.abs() + g.a3.abs());
    let mut worst = Worst::default();
    let shoulders: &[f64] = if rho == 0.0 { &[0.0] } else { &[1.0, -1.0] };
    for &sign in shoulders {
        let shoulder = ShoulderSide::new(g, &p5, &axes, sign * rho, reach, slack);
        let (wrists, n_wrists) = shoulder.wrists(q6_hint, &mut out);
        for wrist in &wrists[..n_wrists] {
            shoulder.elbows(*wrist, &mut out, &mut worst);
        }
    }
    if out.is_empty() {
        // Every branch failed the planar reach check, so `worst` is set.
        return Err(worst.why.unwrap_or(Unreachable::TooFar {
            distance_m: f64::NAN,
            reach_m: reach.1,
        }));
    }
    Ok(out)
}

/// The smallest reach violation seen, to report when nothing is reachable.
struct Worst {
    excess: f64,
    why: Option<Unreachable>,
}

impl Default for Worst {
    fn default() -> Self {
        Self {
            excess: f64::INFINITY,
            why: None,
        }
    }
}

/// One wrist solution: (q5, q6, q234, cos q234, sin q234, wrist sign).
type WristSolution = (f64, f64, f64, f64, f64, f64);

/// One shoulder branch: q1 and the target in frame 1, what its wrist and elbow solutions need.
struct ShoulderSide<'a> {
    g: &'a UrGeometry,
    slack: &'a Slack,
    rho_s: f64,
    q1: f64,
    /// The flange's x, y and z axes in frame 1.
    x16: [f64; 3],
    y16: [f64; 3],
    z16: [f64; 3],
    /// The wrist point in the arm plane.
    px: f64,
    py: f64,
    /// (shortest, longest) reach of the planar pair.
    reach: (f64, f64),
}

impl<'a> ShoulderSide<'a> {
    #[inline]
    fn new(
        g: &'a UrGeometry,
        p5: &[f64; 3],
        axes: &[[f64; 3]; 3],
        rho_s: f64,
        reach: (f64, f64),
        slack: &'a Slack,
    ) -> Self {
        // q1 = ψ + atan2(d4, ρ) with ψ = atan2(p5y, p5x), so (cos q1, sin q1) ∝
        // (p5x ρ − p5y d4, p5y ρ + p5x d4): no trigonometry needed.
        let (mut c1, mut s1) = (p5[0] * rho_s - p5[1] * g.d4, p5[1] * rho_s + p5[0] * g.d4);
        let n1 = (c1 * c1 + s1 * s1).sqrt();
        if n1 > 0.0 {
            c1 /= n1;
            s1 /= n1;
        } else {
            // Only with calibration slack: the wrist point on the base axis, any q1 will do.
            (c1, s1) = (1.0, 0.0);
        }
        // Frame-1 components: x1 = (c1, s1, 0), y1 = (0, 0, 1), z1 = (s1, −c1, 0).
        let to1 = |v: &[f64; 3]| [v[0] * c1 + v[1] * s1, v[2], v[0] * s1 - v[1] * c1];
        Self {
            g,
            slack,
            rho_s,
            q1: s1.atan2(c1),
            x16: to1(&axes[0]),
            y16: to1(&axes[1]),
            z16: to1(&axes[2]),
            // WristSolution point in the arm plane (its z1 component is d4 by construction of q1).
            px: p5[0] * c1 + p5[1] * s1,
            py: p5[2] - g.d1,
            reach,
        }
    }

    /// sin q5 cos q6, −sin q5 sin q6, cos q5, and |sin q5| (the wrist's tilt).
    #[inline]
    fn wrist_terms(&self) -> (f64, f64, f64, f64) {
        let a = self.x16[2];
        let b = self.y16[2];
        (a, b, self.z16[2], (a * a + b * b).sqrt())
    }

    /// The wrist solutions (one at a wrist singularity, where `q6_hint` picks q6; else the
    /// noflip and the flip).
    #[inline]
    fn wrists(&self, q6_hint: f64, out: &mut Solutions) -> ([WristSolution; 2], usize) {
        let (g, x16, y16, z16) = (self.g, &self.x16, &self.y16, &self.z16);
        let (a, b, c5, s5abs) = self.wrist_terms();
        let mut wrists = [(0.0, 0.0, 0.0, 0.0, 0.0, 0.0); 2];
        if s5abs < WRIST_SINGULAR_EPS {
            out.singular.wrist = true;
            // R16 = Rz(q234 ± q6) (·diag(−1, 1, −1) when q5 = π): only φ = q234 ± q6 is known.
            let (q5, phi, s6dir) = if c5 >= 0.0 {
                (0.0, x16[1].atan2(x16[0]), -1.0)
            } else {
                (PI, (-x16[1]).atan2(-x16[0]), 1.0)
            };
            // q234 = φ + s6dir·q6 for the hinted q6; move it to the nearest reachable value.
            let wanted = phi + s6dir * q6_hint;
            let (reach_min, reach_max) = self.reach;
            let q234 = nearest_reachable_q234(g, self.px, self.py, wanted, reach_min, reach_max);
            let q6 = wrap_pi(s6dir * (q234 - phi));
            let (s234, c234) = q234.sin_cos();
            wrists[0] = (q5, q6, q234, c234, s234, 1.0);
            return (wrists, 1);
        }
        // WristSolution noflip (sin q5 > 0); the flip is q5 → −q5, q6 → q6 + π, q234 → q234 + π.
        let q5 = s5abs.atan2(c5);
        let (c6, s6) = (a / s5abs, -b / s5abs);
        let q6 = (-b).atan2(a);
        // First column of Rz(q234) = R16 · (c5 c6, −c5 s6, −s5).
        let (u, v, w) = (c5 * c6, -c5 * s6, -s5abs);
        let mut c234 = x16[0] * u + y16[0] * v + z16[0] * w;
        let mut s234 = x16[1] * u + y16[1] * v + z16[1] * w;
        let n = (c234 * c234 + s234 * s234).sqrt();
        c234 /= n;
        s234 /= n;
        let q234 = s234.atan2(c234);
        wrists[0] = (q5, q6, q234, c234, s234, 1.0);
        wrists[1] = (-q5, flip_pi(q6), flip_pi(q234), -c234, -s234, -1.0);
        (wrists, 2)
    }

    /// WristSolution 1's point in the arm plane for q234, its squared distance from the shoulder, and
    /// the cosine of q3 that reaches it.
    #[inline]
    fn planar_cos(&self, s234: f64, c234: f64) -> (f64, f64, f64, f64) {
        let g = self.g;
        let p4x = self.px - g.d5 * s234;
        let p4y = self.py + g.d5 * c234;
        let dist2 = p4x * p4x + p4y * p4y;
        (
            p4x,
            p4y,
            dist2,
            (dist2 - g.a2 * g.a2 - g.a3 * g.a3) / (2.0 * g.a2 * g.a3),
        )
    }

    /// The elbow pair of one wrist solution into `out`, or its reach violation into `worst`.
    #[inline]
    fn elbows(&self, wrist: WristSolution, out: &mut Solutions, worst: &mut Worst) {
        let (q5, mut q6, mut q234, mut c234, mut s234, sign5) = wrist;
        let (g, slack) = (self.g, self.slack);
        let (_, _, c5, tilt) = self.wrist_terms();
        let (reach_min, reach_max) = self.reach;
        let (mut p4x, mut p4y, mut dist2, mut c3) = self.planar_cos(s234, c234);
        if c3.abs() > 1.0 + slack.cos3 && tilt > 0.0 && tilt < WRIST_NEAR_SINGULAR {
            // Near a wrist singularity, q234 and q6 are split only to ~1e-16/tilt: move within
            // that split to the nearest q234 that puts wrist 1 within reach, if the
            // orientation error it costs (≈ tilt·|Δ|) is negligible.
            let moved = nearest_reachable_q234(g, self.px, self.py, q234, reach_min, reach_max);
            let delta = angle_diff(moved, q234);
            if tilt * delta.abs() < WRIST_SPLIT_ERROR {
                q234 = moved;
                q6 = wrap_pi(if c5 >= 0.0 { q6 - delta } else { q6 + delta });
                (s234, c234) = q234.sin_cos();
                (p4x, p4y, dist2, c3) = self.planar_cos(s234, c234);
            }
        }
        if c3.abs() > 1.0 + slack.cos3 {
            let dist = dist2.sqrt();
            let (excess, why) = if c3 > 0.0 {
                (
                    dist - reach_max,
                    Unreachable::TooFar {
                        distance_m: dist,
                        reach_m: reach_max,
                    },
                )
            } else {
                (
                    reach_min - dist,
                    Unreachable::TooClose {
                        distance_m: dist,
                        min_m: reach_min,
                    },
                )
            };
            if excess < worst.excess {
                worst.excess = excess;
                worst.why = Some(why);
            }
            return;
        }
        c3 = c3.clamp(-1.0, 1.0);
        let mut s3abs = ((1.0 - c3) * (1.0 + c3)).sqrt();
        if s3abs < slack.split_sin3 {
            s3abs = slack.split_sin3;
            c3 = c3.signum() * (1.0 - s3abs * s3abs).sqrt();
        }
        let merged = s3abs < ELBOW_MERGE_SIN;
        if merged {
            out.singular.elbow = true;
            s3abs = 0.0;
            c3 = c3.signum();
        }
        // The elbow pair: q3 = ±atan2(s3, c3), q2 = base ∓ atan2(a3 s3, a2 + a3 c3).
        let base = p4y.atan2(p4x);
        let q3p = s3abs.atan2(c3);
        let off = (g.a3 * s3abs).atan2(g.a2 + g.a3 * c3);
        let elbows: &[f64] = if merged { &[1.0] } else { &[1.0, -1.0] };
        for &sign3 in elbows {
            let q3 = sign3 * q3p;
            let q2 = wrap_pi(base - sign3 * off);
            let q4 = wrap_pi(q234 - q2 - q3);
            let joints = [self.q1, q2, q3, q4, q5, q6];
            let branch = label(self.rho_s, sign3 * s3abs, sign5);
            push_distinct(out, IkSolution { joints, branch });
        }
    }
}

/// `a + π` wrapped into `(−π, π]`, for `a` in `(−π, π]`.
#[inline]
fn flip_pi(a: f64) -> f64 {
    if a > 0.0 { a - PI } else { a + PI }
}

/// Angle difference wrapped into `(−π, π]`.
#[inline]
fn angle_diff(a: f64, b: f64) -> f64 {
    wrap_pi(a - b)
}

pub(crate) fn push_distinct(out: &mut Solutions, s: IkSolution) {
    let dup = out.iter().any(|o| {
        o.joints
            .iter()
            .zip(s.joints.iter())
            .all(|(x, y)| angle_diff(*x, *y).abs() <= MERGE_TOL)
    });
    if !dup {
        out.push(s);
    }
}

/// At a wrist singularity, the `q234` nearest `wanted` for which wrist 1 is within the planar
/// reach `[reach_min, reach_max]` of the shoulder, given the wrist point `(px, py)` in the arm plane.
///
/// `|p4|² = L² + d5² − 2·d5·L·sin(q234 − β)` with `L = |(px, py)|`, `β = atan2(py, px)`, so the
/// reachable set is `sin(q234 − β) ∈ [lo, hi]`: one or two arcs whose ends are candidates.
fn nearest_reachable_q234(
    g: &UrGeometry,
    px: f64,
    py: f64,
    wanted: f64,
    reach_min: f64,
    reach_max: f64,
) -> f64 {
    let l = px.hypot(py);
    if l == 0.0 || g.d5 == 0.0 {
        return wrap_pi(wanted);
    }
    let beta = py.atan2(px);
    let two_dl = 2.0 * g.d5 * l;
    let base = l * l + g.d5 * g.d5;
    let lo = (base - reach_max * reach_max) / two_dl;
    let hi = (base - reach_min * reach_min) / two_dl;
    let u0 = wrap_pi(wanted - beta);
    let s0 = u0.sin();
    if s0 >= lo && s0 <= hi {
        return wrap_pi(wanted);
    }
    let mut best = wrap_pi(wanted);
    let mut best_dist = f64::INFINITY;
    for v in [lo, hi] {
        // A bound a hair beyond ±1 (rounding) is the arc's single tangent point.
        if v.abs() > 1.0 + 1e-9 {
            continue;
        }
        let asin = v.clamp(-1.0, 1.0).asin();
        for u in [asin, PI - asin] {
            let d = angle_diff(u, u0).abs();
            if d < best_dist {
                best_dist = d;
                best = wrap_pi(u + beta);
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dh::DhParams;
    use crate::model::Model;
    use std::f64::consts::FRAC_PI_2;

    fn fk(g: &UrGeometry, q: &[f64; 6]) -> Isometry3<f64> {
        DhParams::nominal(g).flange(q)
    }

    #[test]
    fn eight_solutions_on_a_generic_pose_each_on_its_own_branch() {
        let g = Model::Ur5e.spec().geometry;
        let q = [0.1, -1.2, 1.3, -0.4, 0.7, 0.2];
        let t = fk(&g, &q);
        let sols = solve(&g, &t, 0.0).unwrap();
        assert_eq!(sols.len(), 8);
        let mut branches: Vec<_> = sols.iter().map(|s| s.branch).collect();
        branches.sort_by_key(|b| format!("{b}"));
        branches.dedup();
        assert_eq!(branches.len(), 8, "every solution on its own branch");
        for s in &sols {
            let back = fk(&g, &s.joints);
            assert!(mocomp_geom::translation_error(&back, &t) < 1e-12);
            assert!(mocomp_geom::rotation_error(&back, &t) < 1e-12);
            assert_eq!(BranchCoordinates::of(&g, &s.joints).branch(), s.branch);
        }
        assert!(sols.iter().any(|s| {
            s.joints
                .iter()
                .zip(q.iter())
                .all(|(a, b)| (a - b).abs() < 1e-12)
        }));
    }

    #[test]
    fn typical_working_pose_is_left_up_noflip() {
        // The pose of ur_rtde's moveJ example: arm reaching forward, elbow high, tool down.
        let g = Model::Ur5e.spec().geometry;
        let q = [-1.54, -1.83, -2.28, -0.59, 1.60, 0.023];
        let b = BranchCoordinates::of(&g, &q).branch();
        assert_eq!(
            b,
            Branch {
                shoulder: Shoulder::Left,
                elbow: Elbow::Up,
                wrist: Wrist::NoFlip
            }
        );
        // Elbow geometrically above the shoulder–wrist 1 line: check in the base frame.
        let f = DhParams::nominal(&g).frames(&q);
        let (sh, el, wr) = (
            f[1].translation.vector,
            f[2].translation.vector,
            f[3].translation.vector,
        );
        let t = (el - sh).dot(&(wr - sh)) / (wr - sh).norm_squared();
        let on_line = sh + (wr - sh) * t;
        assert!(el.z > on_line.z, "elbow above the shoulder–wrist line");
    }

    #[test]
    fn home_pose_is_wrist_and_elbow_singular() {
        // UR's home pose (upright): q5 = 0 and q3 = 0, wrist and elbow singular at once (the peer
        // ur-analytic-ik returns nothing here).
        let g = Model::Ur5e.spec().geometry;
        let q = [0.0, -FRAC_PI_2, 0.0, -FRAC_PI_2, 0.0, 0.0];
        let t = fk(&g, &q);
        // Upright, the wrist point also lies in the plane of axes 1 and 2: shoulder singular too.
        let sols = solve(&g, &t, 0.0).unwrap();
        assert_eq!(
            sols.singular,
            SingularCases {
                shoulder: true,
                elbow: true,
                wrist: true
            }
        );
        assert_eq!(sols.len(), 1, "shoulder, elbow and flip pairs all merged");
        assert!(sols.iter().any(|s| {
            s.joints
                .iter()
                .zip(q.iter())
                .all(|(a, b)| (a - b).abs() < 1e-9)
        }));
        for hint in [0.7, -2.0] {
            // The wrist point is at the farthest reach (|a2| + |a3| + d5): every other q6 would
            // put wrist 1 out of reach, so q6 = 0 is the nearest reachable value to any hint.
            let sols = solve(&g, &t, hint).unwrap();
            assert_eq!(sols.len(), 1);
            for s in &sols {
                assert!(
                    s.joints[5].abs() < 1e-6,
                    "q6 = {} for hint {hint}",
                    s.joints[5]
                );
                let back = fk(&g, &s.joints);
                assert!(mocomp_geom::translation_error(&back, &t) < 1e-12);
                assert!(mocomp_geom::rotation_error(&back, &t) < 1e-12);
            }
        }
    }

    #[test]
    fn wrist_singular_keeps_hint_or_nearest_reachable_q6() {
        let g = Model::Ur3.spec().geometry;
        let q = [0.3, -1.0, 1.2, -0.5, 0.0, 0.4];
        let t = fk(&g, &q);
        let sols = solve(&g, &t, 0.4).unwrap();
        assert!(sols.singular.wrist);
        // The wrist is singular on this shoulder root only (q5 depends on q1): 2 elbows there,
        // 2 elbows × 2 wrists on the other root.
        assert_eq!(sols.len(), 6);
        let singular: Vec<_> = sols.iter().filter(|s| s.joints[4] == 0.0).collect();
        assert_eq!(singular.len(), 2);
        assert!(singular.iter().all(|s| s.joints[5] == 0.4));
        assert!(sols.iter().any(|s| {
            s.joints
                .iter()
                .zip(q.iter())
                .all(|(a, b)| (a - b).abs() < 1e-9)
        }));
        // A nearly stretched arm: most q6 values would push wrist 1 out of reach. The solver must
        // still find the pose, moving q6 only as far as needed.
        let q = [0.3, -0.6, 0.02, -0.5, 0.0, 0.4];
        let t = fk(&g, &q);
        for hint in [0.4, 2.0, -2.5] {
            let sols = solve(&g, &t, hint).unwrap();
            assert!(!sols.is_empty());
            for s in &sols {
                let back = fk(&g, &s.joints);
                assert!(
                    mocomp_geom::translation_error(&back, &t) < 1e-10,
                    "hint {hint}"
                );
                assert!(mocomp_geom::rotation_error(&back, &t) < 1e-10);
            }
        }
    }

    #[test]
    fn unreachable_poses_say_why() {
        let g = Model::Ur3.spec().geometry;
        let far = Isometry3::translation(2.0, 0.0, 0.2);
        match solve(&g, &far, 0.0) {
            Err(Unreachable::TooFar {
                distance_m,
                reach_m,
            }) => {
                assert!(distance_m > reach_m);
                assert!((reach_m - 0.4569).abs() < 1e-12);
            }
            other => panic!("expected TooFar, got {other:?}"),
        }
        // Tool axis vertical, wrist point on the base axis: inside the d4 cylinder.
        let inside = Isometry3::translation(0.0, 0.0, 0.3);
        assert!(matches!(
            solve(&g, &inside, 0.0),
            Err(Unreachable::InsideShoulderCylinder { .. })
        ));
    }
}
