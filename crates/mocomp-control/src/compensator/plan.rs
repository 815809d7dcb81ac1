//! Target, while approaching: the way from where the coil is to the goal around the head (a
//! shell path on the current IK branch, or a joint-space transit to the goal's approach axis on
//! the branch the approach needs, [`crate::transit`]), checked before it is taken, and the step
//! along it each cycle.

use super::check::link_point;
use super::{Compensator, CycleRecord, Plan};
use crate::planner::{PlanError, ShellPath};
use crate::safety::backed_off;
use crate::supervisor::{Reason, TransitRefusal};
use crate::transit::{JointPath, profile_step};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::{BranchPolicy, Metric, Selection};

/// Samples along a planned path checked for reachability and collisions.
const PATH_CHECKS: usize = 40;
/// Largest joint change between neighbouring path samples before it counts as a branch change,
/// rad.
const MAX_PATH_JOINT_STEP: f64 = 0.35;
/// A joint-space transit is checked against the head at samples this far apart (the largest
/// joint's travel), rad: 2 cm at a 0.4 m lever.
const TRANSIT_CHECK_RAD: f64 = 0.05;
/// A transit's profile waits while the command lags it by more than this (largest joint), rad.
const TRANSIT_LAG_RAD: f64 = 0.02;
/// A transit has arrived when the command is this close to its end (largest joint), rad.
const TRANSIT_ARRIVED_RAD: f64 = 1e-4;

/// The approach's state: the planned way and the progress along it.
#[derive(Debug, Clone, Default)]
pub(super) struct ApproachState {
    /// The planned way to the goal while approaching.
    pub(super) path: Option<Plan>,
    /// Progress along it: m of shell path, or rad of the transit's largest joint.
    pub(super) sigma: f64,
    pub(super) sigma_dot: f64,
    /// The next resume plans a path, whatever the distance (a new goal, a refusal near the head).
    pub(super) replan: bool,
}

/// What a step along a shell path gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum ShellStep {
    /// On the way: these joints.
    On([f64; 6]),
    /// At the goal: these joints, then tracking.
    Arrived([f64; 6]),
    /// The path's next pose has no IK solution on this branch.
    Unreachable,
}

/// The largest joint difference between `q` and `r`, rad.
fn joint_gap(q: &[f64; 6], r: &[f64; 6]) -> f64 {
    (0..6).fold(0.0f64, |m, j| m.max((q[j] - r[j]).abs()))
}

impl Compensator {
    /// Plans the way from the commanded pose to the goal around the head at `base_from_head`: a
    /// shell path when the coil is near the head and the path has a solution on the current
    /// branch, else a joint-space transit to the goal's approach axis away from the head on a
    /// branch the approach has a solution on (see [`crate::transit`]).
    pub(super) fn plan(&self, base_from_head: &Isometry3<f64>) -> Result<Plan, Reason> {
        let p = &self.cfg.params;
        let clearance = self.coil_distance(&self.head_from_coil_at(&self.cmd.q, base_from_head));
        let near = clearance <= p.transit_distance_m + p.shell_distance_m;
        let shell = if near {
            match self.plan_shell(&self.cmd.q, base_from_head) {
                Ok(path) => return Ok(Plan::Shell(path)),
                // A goal whose axis points out of the head has no approach on any branch.
                Err(Reason::GoalAxisOutward) => return Err(Reason::GoalAxisOutward),
                Err(r) => Some(r),
            }
        } else {
            None
        };
        match self.plan_transit(base_from_head) {
            Ok(t) => Ok(Plan::Transit(t)),
            // Near the head with no transit either: the shell's own reason says where it failed.
            Err(Reason::NoTransit(TransitRefusal::Unreachable)) if shell.is_some() => {
                Err(shell.unwrap_or(Reason::NoPath(f64::NAN)))
            }
            Err(r) => Err(r),
        }
    }

    /// A shell path from the coil at joints `q` to the goal around the head at
    /// `base_from_head`, checked: every sample reachable on `q`'s branch with no joint jump, and
    /// every step between samples collision-free.
    fn plan_shell(
        &self,
        q: &[f64; 6],
        base_from_head: &Isometry3<f64>,
    ) -> Result<ShellPath, Reason> {
        let start = self.head_from_coil_at(q, base_from_head);
        let path = ShellPath::plan(
            &self.cfg.head,
            &start,
            &self.cfg.head_from_coil_goal,
            self.cfg.params.shell_distance_m,
        )
        .map_err(|e| match e {
            PlanError::AxisOutward => Reason::GoalAxisOutward,
            PlanError::NoRetreat(_) => Reason::NoPath(f64::NAN),
        })?;
        let mut q = *q;
        let n = PATH_CHECKS;
        for k in 1..=n {
            let sigma = path.length() * k as f64 / n as f64;
            let flange =
                base_from_head * path.pose_at(&self.cfg.head, sigma) * self.coil_from_flange;
            let next = self
                .arm
                .ik_closest(
                    &flange,
                    &q,
                    &Selection::tracking(self.cfg.params.joint_margin_rad),
                )
                .map_err(|_| Reason::NoPath(sigma))?
                .joints;
            if joint_gap(&next, &q) > MAX_PATH_JOINT_STEP
                || self
                    .collision(&q, &next, base_from_head, base_from_head)
                    .is_some()
            {
                return Err(Reason::NoPath(sigma));
            }
            q = next;
        }
        Ok(path)
    }

    /// A joint-space transit from the command to the goal's approach axis `transit_distance_m`
    /// back from the goal, for the head at `base_from_head`: of the IK solutions there (each
    /// branch, the `±2π` variant nearest the command), the quickest whose configuration is clear
    /// of singularities, whose straight joint-space line stays clear of the head, and from which
    /// the shell path to the goal has a solution. Refused with the furthest any candidate got.
    fn plan_transit(&self, base_from_head: &Isometry3<f64>) -> Result<JointPath, Reason> {
        let p = &self.cfg.params;
        let pre = backed_off(&self.cfg.head_from_coil_goal, p.transit_distance_m);
        let flange = base_from_head * pre * self.coil_from_flange;
        let refused = |why| Reason::NoTransit(why);
        let sols = self
            .arm
            .ik(&flange, self.cmd.q[5])
            .map_err(|_| refused(TransitRefusal::Unreachable))?;
        // Each branch's variant nearest the command, quickest first (at most 8: no allocation).
        let mut cands = [(f64::INFINITY, [0.0; 6]); 8];
        let mut n = 0;
        for s in sols.iter().take(cands.len()) {
            let sel = Selection {
                metric: Metric::TimeToReach,
                branch: BranchPolicy::Only(s.branch),
                limit_margin: p.joint_margin_rad,
            };
            if let Ok(c) = self.arm.choose(&sols, &self.cmd.q, &sel) {
                cands[n] = (c.cost, c.joints);
                n += 1;
            }
        }
        cands[..n].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut furthest = TransitRefusal::Unreachable;
        for (_, q) in &cands[..n] {
            let path = JointPath::new(self.cmd.q, *q);
            let why = if self.arm.singularity_margin(q) < p.singularity_slow {
                TransitRefusal::Singular
            } else if !self.transit_clear(&path, base_from_head) {
                TransitRefusal::Collision
            } else if self.plan_shell(q, base_from_head).is_err() {
                TransitRefusal::NoApproach
            } else {
                return Ok(path);
            };
            furthest = furthest.max(why);
        }
        Err(refused(furthest))
    }

    /// Whether a transit stays clear of the head at `base_from_head` all along: the coil never
    /// closer than the shell (or than it starts, when it starts nearer), no link closer than its
    /// clearance.
    fn transit_clear(&self, path: &JointPath, base_from_head: &Isometry3<f64>) -> bool {
        let p = &self.cfg.params;
        let head_from_base = base_from_head.inverse();
        let start = self.coil_distance(&self.head_from_coil_at(path.start(), base_from_head));
        let coil_min = p.shell_distance_m.min(start - p.coil_contact_tolerance_m);
        let n = ((path.length() / TRANSIT_CHECK_RAD).ceil() as usize).clamp(1, 200);
        for k in 1..=n {
            let q = path.at(path.length() * k as f64 / n as f64);
            if self.coil_distance(&self.head_from_coil_at(&q, base_from_head)) < coil_min {
                return false;
            }
            let frames = self.arm.link_frames(&q);
            for i in 1..6 {
                for s in 0..=4 {
                    let point = link_point(&frames, i, s);
                    let d = self.cfg.head.distance(&(head_from_base * point)) - p.link_radius_m;
                    if d < p.link_clearance_m {
                        return false;
                    }
                }
            }
        }
        true
    }

    /// One step along a transit: in joint space, the head's motion aside (the checks on every
    /// command still see it); the shell path follows from its end, planned on arrival.
    pub(super) fn transit_step(&mut self, t: &JointPath) -> [f64; 6] {
        let p = &self.cfg.params;
        let a = &mut self.approach;
        let want = if joint_gap(&self.cmd.q, &t.at(a.sigma)) < TRANSIT_LAG_RAD {
            p.transit_speed_rad_s
        } else {
            0.0
        };
        (a.sigma, a.sigma_dot) = profile_step(
            a.sigma,
            a.sigma_dot,
            t.length(),
            want,
            p.transit_accel_rad_s2,
            self.cmd.dt,
        );
        if a.sigma >= t.length() && joint_gap(&self.cmd.q, t.end()) < TRANSIT_ARRIVED_RAD {
            a.path = None;
            a.replan = true;
        }
        t.at(a.sigma)
    }

    /// One step along a shell path for the head at `base_from_head`.
    pub(super) fn shell_step(
        &mut self,
        path: &ShellPath,
        base_from_head: &Isometry3<f64>,
        rec: &mut CycleRecord,
    ) -> ShellStep {
        let target = self.path_target(path, base_from_head);
        rec.path = Some((self.approach.sigma, path.length()));
        let step = self.arm.ik_closest(
            &target,
            &self.cmd.q,
            &Selection::tracking(self.cfg.params.joint_margin_rad),
        );
        match step {
            Err(_) => {
                self.approach.path = None;
                ShellStep::Unreachable
            }
            Ok(c) if self.approach.sigma >= path.length() => {
                self.approach.path = None;
                ShellStep::Arrived(c.joints)
            }
            Ok(c) => ShellStep::On(c.joints),
        }
    }

    /// Advances along the path (a speed-limited, acceleration-limited arc-length profile that
    /// waits for the command when it lags) and returns the flange target at the new arc length.
    fn path_target(&mut self, path: &ShellPath, base_from_head: &Isometry3<f64>) -> Isometry3<f64> {
        let dt = self.cmd.dt;
        let p = &self.cfg.params;
        let a = p.approach_accel_m_s2;
        let here = base_from_head
            * path.pose_at(&self.cfg.head, self.approach.sigma)
            * self.coil_from_flange;
        let lag =
            (self.arm.fk_flange(&self.cmd.q).translation.vector - here.translation.vector).norm();
        let remaining = (path.length() - self.approach.sigma).max(0.0);
        let want = if lag < p.path_lag_m {
            p.approach_speed_m_s.min((2.0 * a * remaining).sqrt())
        } else {
            0.0
        };
        let s = &mut self.approach;
        s.sigma_dot = want.clamp(s.sigma_dot - a * dt, s.sigma_dot + a * dt);
        if p.force_sensing && self.force.axial_n > p.contact_force_n {
            // Touching before the path's end: stop where it touches, at once.
            s.sigma_dot = 0.0;
        }
        s.sigma = (s.sigma + s.sigma_dot * dt).min(path.length());
        base_from_head * path.pose_at(&self.cfg.head, s.sigma) * self.coil_from_flange
    }

    /// Takes a new plan, with progress from its start.
    pub(super) fn take_plan(&mut self, plan: Plan) {
        self.approach.path = Some(plan);
        (self.approach.sigma, self.approach.sigma_dot) = (0.0, 0.0);
        self.approach.replan = false;
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::super::tests::{at_goal, fixture};
    use super::*;
    use mocomp_testkit::scene::head_rest;

    #[test]
    fn near_the_head_the_way_is_a_shell_path_and_from_afar_a_transit() {
        let (mut c, _) = fixture();
        let bh = head_rest();
        // Backed off 3 cm along the axis from the goal: near, on the goal's branch.
        c.cmd.q = at_goal(&c, 0.03);
        match c.plan(&bh) {
            Ok(Plan::Shell(p)) => assert!(p.length() > 0.02, "{}", p.length()),
            other => panic!("{other:?}"),
        }
        // UR's home pose, far from the head: a transit, clear of it.
        c.cmd.q = [0.0, -1.57, 0.0, -1.57, 0.0, 0.0];
        match c.plan(&bh) {
            Ok(Plan::Transit(t)) => {
                assert!(t.length() > 0.3, "{}", t.length());
                assert!(c.transit_clear(&t, &bh));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_shell_path_is_followed_to_its_end_and_hands_over() {
        let (mut c, _) = fixture();
        let bh = head_rest();
        c.cmd.q = at_goal(&c, 0.03);
        let Ok(Plan::Shell(path)) = c.plan(&bh) else {
            panic!("no shell path")
        };
        c.take_plan(Plan::Shell(path));
        let mut rec = CycleRecord::new(0.0, c.mode, c.cmd.q);
        let mut last_sigma = 0.0;
        for _ in 0..20_000 {
            match c.shell_step(&path, &bh, &mut rec) {
                ShellStep::On(q) => c.cmd.q = q,
                ShellStep::Arrived(q) => {
                    let goal = at_goal(&c, 0.0);
                    assert!(joint_gap(&q, &goal) < 1e-6, "{q:?} {goal:?}");
                    assert!(c.approach.path.is_none());
                    return;
                }
                ShellStep::Unreachable => panic!("unreachable at {}", c.approach.sigma),
            }
            assert!(c.approach.sigma >= last_sigma, "the path went backwards");
            assert!(c.approach.sigma_dot <= c.cfg.params.approach_speed_m_s + 1e-12);
            last_sigma = c.approach.sigma;
        }
        panic!("never arrived: {} of {}", c.approach.sigma, path.length());
    }
}
