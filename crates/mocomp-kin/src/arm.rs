//! [`Arm`]: one robot's kinematics (model, optional factory calibration, tool, joint limits) with
//! forward kinematics, inverse kinematics, the Jacobian and singularity measures.

use crate::dh::{DhCalibration, DhParams};
use crate::error::KinError;
use crate::ik::{self, BranchCoordinates, Solutions};
use crate::model::{Model, ModelSpec, UrGeometry};
use mocomp_geom::nalgebra::{Isometry3, Matrix6, Translation3, Vector3, Vector6};
use mocomp_geom::rotvec_from_quat;
use mocomp_geom::units::wrap_pi;
use std::f64::consts::TAU;

/// Joint position limits, radians (`±inf` for a joint that turns without limit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointLimits {
    /// Lower limits.
    pub lower: [f64; 6],
    /// Upper limits.
    pub upper: [f64; 6],
}

impl JointLimits {
    /// Checks that every joint's limits form an interval.
    pub fn new(lower: [f64; 6], upper: [f64; 6]) -> Result<Self, KinError> {
        for j in 0..6 {
            if lower[j].is_nan() || upper[j].is_nan() || lower[j] >= upper[j] {
                return Err(KinError::InvalidLimits {
                    joint: j + 1,
                    lower: lower[j],
                    upper: upper[j],
                });
            }
        }
        Ok(Self { lower, upper })
    }

    /// True when every joint is within its limits shrunk by `margin` radians.
    pub fn contains(&self, q: &[f64; 6], margin: f64) -> bool {
        (0..6).all(|j| q[j] >= self.lower[j] + margin && q[j] <= self.upper[j] - margin)
    }

    /// The value `q + 2πk` of joint `j` within its limits (shrunk by `margin`) that is nearest
    /// `near`, or `None` when no such value exists.
    #[inline]
    pub fn nearest_variant(&self, j: usize, q: f64, near: f64, margin: f64) -> Option<f64> {
        let lo = self.lower[j] + margin;
        let hi = self.upper[j] - margin;
        let base = q + TAU * ((near - q) / TAU).round();
        let mut best: Option<f64> = None;
        for v in [base, base - TAU, base + TAU] {
            if v >= lo && v <= hi && best.is_none_or(|b| (v - near).abs() < (b - near).abs()) {
                best = Some(v);
            }
        }
        best
    }

    /// The canonical value of joint `j`'s angle `q`: the `q + 2πk` within the limits nearest the
    /// middle of the range (0 for unlimited or symmetric joints), or `None`.
    pub fn canonical(&self, j: usize, q: f64) -> Option<f64> {
        let (lo, hi) = (self.lower[j], self.upper[j]);
        let mid = if lo.is_finite() && hi.is_finite() {
            0.5 * (lo + hi)
        } else {
            0.0
        };
        if (q - mid).abs() <= std::f64::consts::PI && q >= lo && q <= hi {
            // Every other variant is at least π from the middle.
            return Some(q);
        }
        self.nearest_variant(j, q, mid, 0.0)
    }

    /// Every `q + 2πk` variant of a configuration that stays within the limits, per joint the
    /// shifts `k ∈ {−1, 0, 1}` of the canonical value (the seed paper's "±360° versions"). For UR
    /// limits of ±2π this is 2 values per joint where `|q| > 0`.
    pub fn variants(&self, q: &[f64; 6]) -> Vec<[f64; 6]> {
        let mut per_joint: [[f64; 3]; 6] = [[0.0; 3]; 6];
        let mut counts = [0usize; 6];
        for j in 0..6 {
            for k in [-1.0, 0.0, 1.0] {
                let v = q[j] + k * TAU;
                if v >= self.lower[j] && v <= self.upper[j] && v.abs() <= 2.0 * TAU {
                    per_joint[j][counts[j]] = v;
                    counts[j] += 1;
                }
            }
        }
        let total: usize = counts.iter().product();
        let mut out = Vec::with_capacity(total);
        for mut index in 0..total {
            let mut v = [0.0; 6];
            for j in 0..6 {
                v[j] = per_joint[j][index % counts[j]];
                index /= counts[j];
            }
            out.push(v);
        }
        out
    }
}

/// How close a configuration is to each singularity of the UR arm.
///
/// For the nominal geometry `det J = a2·a3·sin q3·sin q5·ρ` (up to sign), so each factor is a
/// singularity on its own.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Singularity {
    /// Signed reach of the wrist point from the plane of axes 1 and 2, metres (shoulder
    /// singularity at 0).
    pub shoulder_m: f64,
    /// `sin q3` (elbow singularity at 0: arm stretched or folded).
    pub elbow: f64,
    /// `sin q5` (wrist singularity at 0: axes 4 and 6 aligned).
    pub wrist: f64,
    /// Yoshikawa manipulability `√det(J Jᵀ) = |det J|` of the geometric Jacobian, m³.
    pub manipulability: f64,
}

impl Singularity {
    /// A single dimensionless closeness measure in `[0, 1]`: the smallest of `|sin q3|`,
    /// `|sin q5|` and `|ρ|` over the arm's reach `|a2| + |a3|`. Zero at any singularity.
    pub fn margin(&self, g: &UrGeometry) -> f64 {
        let reach = g.a2.abs() + g.a3.abs();
        self.elbow
            .abs()
            .min(self.wrist.abs())
            .min((self.shoulder_m.abs() / reach).min(1.0))
    }
}

/// One robot's kinematics.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arm {
    spec: &'static ModelSpec,
    /// The exact chain (nominal, or the robot's calibration).
    dh: DhParams,
    calibrated: bool,
    limits: JointLimits,
    flange_from_tool: Isometry3<f64>,
    tool_from_flange: Isometry3<f64>,
}

/// Newton refinement for calibrated models: stop below this residual (metres + radians).
const REFINE_TOL: f64 = 1e-13;
/// Accept a refined solution when its residual is below this.
const REFINE_ACCEPT: f64 = 1e-10;
const REFINE_MAX_ITER: usize = 30;

impl Arm {
    /// The nominal kinematics of a model, no tool, the model's joint limits.
    pub fn new(model: Model) -> Self {
        let spec = model.spec();
        Self {
            spec,
            dh: DhParams::nominal(&spec.geometry),
            calibrated: false,
            limits: JointLimits {
                lower: spec.lower_limits,
                upper: spec.upper_limits,
            },
            flange_from_tool: Isometry3::identity(),
            tool_from_flange: Isometry3::identity(),
        }
    }

    /// The kinematics of a robot with its own calibrated DH values.
    pub fn calibrated(calibration: &DhCalibration) -> Result<Self, KinError> {
        calibration.validate()?;
        let mut arm = Self::new(calibration.model);
        arm.dh = calibration.dh;
        arm.calibrated = true;
        Ok(arm)
    }

    /// The same arm with a tool: `flange_from_tool` maps tool-frame points into the flange frame.
    /// FK, IK and the Jacobian then refer to the tool frame (the TCP).
    pub fn with_tool(mut self, flange_from_tool: Isometry3<f64>) -> Self {
        self.flange_from_tool = flange_from_tool;
        self.tool_from_flange = flange_from_tool.inverse();
        self
    }

    /// The same arm with other joint limits.
    pub fn with_limits(mut self, limits: JointLimits) -> Self {
        self.limits = limits;
        self
    }

    /// The model.
    pub fn model(&self) -> Model {
        self.spec.model
    }

    /// The model's table row.
    pub fn spec(&self) -> &'static ModelSpec {
        self.spec
    }

    /// The nominal geometry (used by the closed form and the branch labels).
    pub fn geometry(&self) -> &UrGeometry {
        &self.spec.geometry
    }

    /// The exact DH chain in use.
    pub fn dh(&self) -> &DhParams {
        &self.dh
    }

    /// Whether a factory calibration is loaded.
    pub fn is_calibrated(&self) -> bool {
        self.calibrated
    }

    /// The joint limits.
    pub fn limits(&self) -> &JointLimits {
        &self.limits
    }

    /// The tool offset `flange_from_tool`.
    pub fn flange_from_tool(&self) -> &Isometry3<f64> {
        &self.flange_from_tool
    }

    /// `base_from_flange` at joints `q`.
    pub fn fk_flange(&self, q: &[f64; 6]) -> Isometry3<f64> {
        if self.calibrated {
            self.dh.flange(q)
        } else {
            fk_nominal(&self.spec.geometry, q)
        }
    }

    /// `base_from_tool` at joints `q` (the flange when no tool is set).
    pub fn fk(&self, q: &[f64; 6]) -> Isometry3<f64> {
        self.fk_flange(q) * self.flange_from_tool
    }

    /// Every link frame `[base, base_from_link1, …, base_from_link6 (flange)]`, for planners and
    /// collision checks. Append [`Self::flange_from_tool`] for the tool.
    pub fn link_frames(&self, q: &[f64; 6]) -> [Isometry3<f64>; 7] {
        self.dh.frames(q)
    }

    /// The geometric Jacobian of the tool frame in the base frame: rows 0–2 the linear velocity of
    /// the tool origin (m/s), rows 3–5 the angular velocity (rad/s), per unit joint speed.
    pub fn jacobian(&self, q: &[f64; 6]) -> Matrix6<f64> {
        let frames = self.dh.frames(q);
        let tool = frames[6] * self.flange_from_tool;
        jacobian_at(&frames, &tool.translation.vector)
    }

    /// How close `q` is to each singularity.
    pub fn singularity(&self, q: &[f64; 6]) -> Singularity {
        let c = BranchCoordinates::of(&self.spec.geometry, q);
        Singularity {
            shoulder_m: c.rho_m,
            elbow: c.sin_q3,
            wrist: c.sin_q5,
            manipulability: self.jacobian(q).determinant().abs(),
        }
    }

    /// [`Singularity::margin`] at `q`, without the Jacobian's determinant the full
    /// [`Self::singularity`] also computes (the control loop needs only the margin, every cycle).
    pub fn singularity_margin(&self, q: &[f64; 6]) -> f64 {
        let c = BranchCoordinates::of(&self.spec.geometry, q);
        Singularity {
            shoulder_m: c.rho_m,
            elbow: c.sin_q3,
            wrist: c.sin_q5,
            manipulability: f64::NAN,
        }
        .margin(&self.spec.geometry)
    }

    /// All IK solutions (up to 8, distinct, each labelled with its branch) for `base_from_tool`.
    ///
    /// Joint values are canonical within the limits (for UR's ±2π limits: in `(−π, π]`);
    /// solutions with no value inside the limits are dropped. `q6_hint` (the current wrist 3
    /// angle) decides `q6` at a wrist singularity. With a calibrated model, each closed-form
    /// solution of the nominal geometry is refined by Newton steps against the exact chain.
    pub fn ik(&self, base_from_tool: &Isometry3<f64>, q6_hint: f64) -> Result<Solutions, KinError> {
        check_pose_finite(base_from_tool)?;
        let target = base_from_tool * self.tool_from_flange;
        let g = &self.spec.geometry;
        let mut sols = if self.calibrated {
            self.ik_calibrated(&target, q6_hint)?
        } else {
            ik::solve(g, &target, q6_hint).map_err(KinError::Unreachable)?
        };
        let found = sols.len();
        let limits = self.limits;
        sols.retain(|s| {
            for j in 0..6 {
                match limits.canonical(j, s.joints[j]) {
                    Some(v) => s.joints[j] = v,
                    None => return false,
                }
            }
            true
        });
        if sols.is_empty() {
            return Err(KinError::OutsideJointLimits { solutions: found });
        }
        Ok(sols)
    }

    /// Calibrated IK: lenient closed-form starts on the nominal geometry (the calibrated arm's
    /// reach differs by up to centimetres), each refined against the exact chain; starts that do
    /// not converge are dropped, duplicates merged.
    fn ik_calibrated(
        &self,
        base_from_flange: &Isometry3<f64>,
        q6_hint: f64,
    ) -> Result<Solutions, KinError> {
        let g = &self.spec.geometry;
        let starts = ik::solve_with(g, base_from_flange, q6_hint, &ik::CALIBRATION_START)
            .map_err(KinError::Unreachable)?;
        let mut out = Solutions::new();
        out.singular = starts.singular;
        let mut best_residual = f64::INFINITY;
        for s in &starts {
            match self.refine(base_from_flange, s.joints) {
                Ok(q) => {
                    let joints = q.map(wrap_pi);
                    let branch = BranchCoordinates::of(g, &joints).branch();
                    ik::push_distinct(&mut out, ik::IkSolution { joints, branch });
                }
                Err(res) => best_residual = best_residual.min(res),
            }
        }
        if out.is_empty() {
            // Tell why in terms of the geometry when the strict closed form also fails.
            return Err(match ik::solve(g, base_from_flange, q6_hint) {
                Err(why) => KinError::Unreachable(why),
                Ok(_) => KinError::NotConverged {
                    residual: best_residual,
                },
            });
        }
        Ok(out)
    }

    /// Newton (Gauss–Newton with damping near singularities) on the exact chain from `q`.
    /// Returns the refined joints, or the residual reached.
    fn refine(&self, base_from_flange: &Isometry3<f64>, mut q: [f64; 6]) -> Result<[f64; 6], f64> {
        let mut residual = f64::INFINITY;
        for _ in 0..REFINE_MAX_ITER {
            let frames = self.dh.frames(&q);
            let e = pose_residual(base_from_flange, &frames[6]);
            residual = e.norm();
            if residual < REFINE_TOL {
                return Ok(q);
            }
            let j = jacobian_at(&frames, &frames[6].translation.vector);
            let dq = match j.lu().solve(&e) {
                Some(dq) if dq.iter().all(|v| v.is_finite()) && dq.norm() < 1.0 => dq,
                _ => {
                    // Damped least squares: (JᵀJ + λ²I) dq = Jᵀ e.
                    let jt = j.transpose();
                    let a = jt * j + Matrix6::identity() * 1e-6;
                    match a.cholesky() {
                        Some(ch) => ch.solve(&(jt * e)),
                        None => return Err(residual),
                    }
                }
            };
            for k in 0..6 {
                q[k] += dq[k];
            }
        }
        if residual < REFINE_ACCEPT {
            Ok(q)
        } else {
            Err(residual)
        }
    }
}

/// `[position error; rotation vector error]` of `actual` against `goal`, in the base frame.
fn pose_residual(goal: &Isometry3<f64>, actual: &Isometry3<f64>) -> Vector6<f64> {
    let dp = goal.translation.vector - actual.translation.vector;
    let dr = rotvec_from_quat(&(goal.rotation * actual.rotation.inverse()));
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// Geometric Jacobian of the point `p` (base frame) from the link frames.
fn jacobian_at(frames: &[Isometry3<f64>; 7], p: &Vector3<f64>) -> Matrix6<f64> {
    let mut j = Matrix6::zeros();
    for i in 0..6 {
        let f = &frames[i];
        let z = f.rotation * Vector3::z();
        let lin = z.cross(&(p - f.translation.vector));
        for r in 0..3 {
            j[(r, i)] = lin[r];
            j[(r + 3, i)] = z[r];
        }
    }
    j
}

fn check_pose_finite(t: &Isometry3<f64>) -> Result<(), KinError> {
    let q = t.rotation.coords;
    let v = t.translation.vector;
    let values = [v.x, v.y, v.z, q.x, q.y, q.z, q.w];
    match values.iter().position(|x| !x.is_finite()) {
        Some(index) => Err(KinError::NonFinite {
            what: "target pose (x, y, z, qx, qy, qz, qw)",
            index,
            value: values[index],
        }),
        None => Ok(()),
    }
}

/// Closed-form forward kinematics of the nominal geometry (six `sin_cos`, no matrix chain).
///
/// In frame 1 the flange orientation is `Rz(q234)·Ry(−q5)·Rz(q6)` and its position
/// `(a2 c2 + a3 c23, a2 s2 + a3 s23, d4) + d5·(s234, −c234, 0) + d6·(−c234 s5, −s234 s5, c5)`;
/// frame 1 is the base rotated by `q1` with `(u, v, w)₁ = (u c1 + w s1, u s1 − w c1, v)` and its
/// origin at height `d1`.
pub fn fk_nominal(g: &UrGeometry, q: &[f64; 6]) -> Isometry3<f64> {
    use mocomp_geom::nalgebra::{Matrix3, Rotation3, UnitQuaternion};
    let (s1, c1) = q[0].sin_cos();
    let (s2, c2) = q[1].sin_cos();
    let q23 = q[1] + q[2];
    let (s23, c23) = q23.sin_cos();
    let (s234, c234) = (q23 + q[3]).sin_cos();
    let (s5, c5) = q[4].sin_cos();
    let (s6, c6) = q[5].sin_cos();
    // Columns of R16.
    let x = [
        c234 * c5 * c6 - s234 * s6,
        s234 * c5 * c6 + c234 * s6,
        s5 * c6,
    ];
    let y = [
        -c234 * c5 * s6 - s234 * c6,
        -s234 * c5 * s6 + c234 * c6,
        -s5 * s6,
    ];
    let z = [-c234 * s5, -s234 * s5, c5];
    let p = [
        g.a2 * c2 + g.a3 * c23 + g.d5 * s234 + g.d6 * z[0],
        g.a2 * s2 + g.a3 * s23 - g.d5 * c234 + g.d6 * z[1],
        g.d4 + g.d6 * z[2],
    ];
    let to_base = |v: [f64; 3]| [v[0] * c1 + v[2] * s1, v[0] * s1 - v[2] * c1, v[1]];
    let (xb, yb, zb, pb) = (to_base(x), to_base(y), to_base(z), to_base(p));
    let r = Matrix3::new(
        xb[0], yb[0], zb[0], xb[1], yb[1], zb[1], xb[2], yb[2], zb[2],
    );
    Isometry3::from_parts(
        Translation3::new(pb[0], pb[1], pb[2] + g.d1),
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r)),
    )
}
