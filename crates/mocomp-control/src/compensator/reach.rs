//! Whether and how the loop can reach a goal for a head at a given place, asked before a
//! session rather than found by holding in one: the way the loop itself would plan from where
//! the arm rests (the same planner, the same checks), the arm's configuration at the goal (its
//! branch, its least margin to a joint limit, its distance to a singularity), and the room it
//! leaves for the head to move there. Pure: no I/O; it plans on a copy of the loop.

use super::{Compensator, Plan};
use crate::supervisor::Reason;
use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use mocomp_kin::{Branch, BranchPolicy, Selection};

/// How far the head may move from its place while the coil follows: rotations about the head
/// marker's three axes and translations along them, each way. A seated patient's nods and
/// drift stay within this (the built-in world's nods are ±0.15 rad, its drift a few cm).
pub const HEADROOM_RAD: f64 = 0.175;
/// The same for translation, m.
pub const HEADROOM_M: f64 = 0.03;

/// The way from the rest to the goal the loop would take.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Way {
    /// Along the safety shell around the head, on the branch the arm rests on.
    Shell,
    /// A joint move to the goal's approach axis (the largest joint's turn, rad), then the shell.
    Transit(f64),
}

/// The arm at the goal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AtGoal {
    /// Its joints, rad.
    pub joints: [f64; 6],
    /// Its branch.
    pub branch: Branch,
    /// The least distance of any joint to its limit, rad.
    pub joint_margin_rad: f64,
    /// [`mocomp_kin::Singularity::margin`]: 0 at a singularity, 1 far from any.
    pub singularity_margin: f64,
    /// Of the head's moves by [`HEADROOM_RAD`] and [`HEADROOM_M`] each way about and along
    /// its axes (12), those the coil can follow on this branch (within the joint margin and
    /// clear of the singularity hold).
    pub headroom_ok: usize,
    /// The least singularity margin over those moves (0 where one has no solution).
    pub headroom_singularity_margin: f64,
}

/// The moves [`AtGoal::headroom_ok`] counts.
pub const HEADROOM_MOVES: usize = 12;

/// Whether and how a goal is reached.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// The way there, or the rule the loop would hold for.
    pub way: Result<Way, Reason>,
    /// The arm at the goal, on the branch the way ends on (`None`: no solution there).
    pub at_goal: Option<AtGoal>,
}

impl Reach {
    /// The rule that keeps the loop from the goal or from following the head there, if any:
    /// no way, no solution at the goal, too near a singularity there, or no room for the head
    /// to move.
    pub fn refusal(&self, slow: f64) -> Option<Reason> {
        if let Err(r) = self.way {
            return Some(r);
        }
        let Some(g) = self.at_goal else {
            return Some(Reason::Unreachable);
        };
        if g.singularity_margin < slow {
            return Some(Reason::Singular(g.singularity_margin));
        }
        if g.headroom_ok < HEADROOM_MOVES {
            return Some(if g.headroom_singularity_margin > 0.0 {
                Reason::Singular(g.headroom_singularity_margin)
            } else {
                Reason::Unreachable
            });
        }
        None
    }

    /// A figure to rank placements by, higher is better, 0 where refused: the least of the
    /// singularity margin and the joint margin (as a share of a half turn) at the goal and over
    /// the head's moves.
    pub fn score(&self, slow: f64) -> f64 {
        match (self.refusal(slow), self.at_goal) {
            (None, Some(g)) => g
                .singularity_margin
                .min(g.headroom_singularity_margin)
                .min(g.joint_margin_rad / std::f64::consts::PI),
            _ => 0.0,
        }
    }
}

/// The head's moves [`AtGoal`] counts: head_from_moved for each.
fn headroom_moves() -> [Isometry3<f64>; HEADROOM_MOVES] {
    let axes = [Vector3::x_axis(), Vector3::y_axis(), Vector3::z_axis()];
    std::array::from_fn(|k| {
        let axis = axes[k % 3];
        let sign = if (k / 3) % 2 == 0 { 1.0 } else { -1.0 };
        if k < 6 {
            Isometry3::from_parts(
                Translation3::identity(),
                UnitQuaternion::from_axis_angle(&axis, sign * HEADROOM_RAD),
            )
        } else {
            Isometry3::from_parts(
                Translation3::from(axis.into_inner() * sign * HEADROOM_M),
                UnitQuaternion::identity(),
            )
        }
    })
}

impl Compensator {
    /// How this loop would reach its goal for the head at `base_from_head` with the arm at
    /// `q_rest`: planned as the loop plans on a copy of it (this one is not changed).
    pub fn reach(&self, q_rest: &[f64; 6], base_from_head: &Isometry3<f64>) -> Reach {
        // A goal the loop refuses outright (inside the head, its axis outward) has no way.
        if let Err(e) = &self.goal.check {
            return Reach {
                way: Err(Reason::from(*e)),
                at_goal: None,
            };
        }
        let mut copy = self.clone();
        copy.cmd.q = *q_rest;
        let planned = copy.plan(base_from_head);
        let (way, from) = match &planned {
            Ok(Plan::Shell(_)) => (Ok(Way::Shell), *q_rest),
            Ok(Plan::Transit(t)) => (Ok(Way::Transit(t.length())), *t.end()),
            Err(r) => (Err(*r), *q_rest),
        };
        Reach {
            way,
            at_goal: self.at_goal(&from, base_from_head),
        }
    }

    /// Whether the arm has a joint solution at the goal for the head at `base_from_head` on
    /// any branch within the joint margin. Without one, [`Self::reach`] finds no arm at the goal
    /// whatever way it plans (it asks for one on a single branch), so a search over placements
    /// asks this first: one IK solve where `reach` plans a path.
    pub fn goal_has_solution(&self, base_from_head: &Isometry3<f64>) -> bool {
        let select = Selection {
            branch: BranchPolicy::Any,
            ..Selection::tracking(self.cfg.params.joint_margin_rad)
        };
        let flange = base_from_head * self.cfg.head_from_coil_goal * self.coil_from_flange;
        self.arm.ik_closest(&flange, &self.cmd.q, &select).is_ok()
    }

    /// The arm at the goal on `from`'s branch, and the room it leaves.
    fn at_goal(&self, from: &[f64; 6], base_from_head: &Isometry3<f64>) -> Option<AtGoal> {
        let p = &self.cfg.params;
        let select = Selection::tracking(p.joint_margin_rad);
        let flange =
            |head: &Isometry3<f64>| head * self.cfg.head_from_coil_goal * self.coil_from_flange;
        let c = self
            .arm
            .ik_closest(&flange(base_from_head), from, &select)
            .ok()?;
        let limits = self.arm.limits();
        let joint_margin_rad = (0..6).fold(f64::INFINITY, |m, j| {
            m.min(c.joints[j] - limits.lower[j])
                .min(limits.upper[j] - c.joints[j])
        });
        let (mut ok, mut least) = (0, f64::INFINITY);
        for moved in headroom_moves() {
            let margin = self
                .arm
                .ik_closest(&flange(&(base_from_head * moved)), &c.joints, &select)
                .map_or(0.0, |m| self.arm.singularity_margin(&m.joints));
            if margin >= p.singularity_hold {
                ok += 1;
            }
            least = least.min(margin);
        }
        Some(AtGoal {
            joints: c.joints,
            branch: c.branch,
            joint_margin_rad,
            singularity_margin: self.arm.singularity_margin(&c.joints),
            headroom_ok: ok,
            headroom_singularity_margin: least,
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::super::tests::{at_goal, fixture};
    use super::*;
    use mocomp_testkit::scene::head_rest;

    #[test]
    fn the_scenes_goal_is_reached_from_its_rest_with_room_for_the_head() {
        let (c, _) = fixture();
        let rest = at_goal(&c, 0.15);
        let r = c.reach(&rest, &head_rest());
        // From 15 cm out, a joint move to the approach axis first; from 2 cm, the shell.
        assert!(matches!(r.way, Ok(Way::Transit(q)) if q > 0.0), "{r:?}");
        let near = c.reach(&at_goal(&c, 0.02), &head_rest());
        assert_eq!(near.way, Ok(Way::Shell), "{near:?}");
        let g = r.at_goal.unwrap();
        assert_eq!(g.headroom_ok, HEADROOM_MOVES, "{g:?}");
        assert!(
            g.joint_margin_rad > 0.0 && g.singularity_margin > 0.1,
            "{g:?}"
        );
        let slow = c.cfg.params.singularity_slow;
        assert_eq!(r.refusal(slow), None);
        assert!(r.score(slow) > 0.0);
        // The copy planned; the loop itself is as it was.
        assert_eq!(c.cmd.q, fixture().0.cmd.q);
    }

    #[test]
    fn a_head_out_of_the_arms_reach_is_refused_as_the_loop_would_hold() {
        let (c, _) = fixture();
        let rest = at_goal(&c, 0.15);
        let far = Isometry3::translation(2.0, 0.0, 0.0) * head_rest();
        let r = c.reach(&rest, &far);
        let slow = c.cfg.params.singularity_slow;
        let why = r.refusal(slow).expect("refused");
        assert!(why.is_placement(), "{why:?}");
        assert!(r.at_goal.is_none(), "{r:?}");
        assert_eq!(r.score(slow), 0.0);
    }

    /// A goal with no joint solution on any branch is one `reach` finds no arm at, and one
    /// with a solution is asked no further by it.
    #[test]
    fn no_solution_at_the_goal_means_no_arm_there_whatever_the_way() {
        let (c, _) = fixture();
        let rest = at_goal(&c, 0.15);
        for k in 0..12 {
            let head = Isometry3::translation(0.06 * k as f64, 0.0, -0.02 * k as f64) * head_rest();
            let quick = c.goal_has_solution(&head);
            let r = c.reach(&rest, &head);
            if !quick {
                assert!(r.at_goal.is_none(), "{k}: {r:?}");
            }
            if k == 0 {
                assert!(quick && r.at_goal.is_some(), "{r:?}");
            }
        }
        assert!(!c.goal_has_solution(&(Isometry3::translation(2.0, 0.0, 0.0) * head_rest())));
    }

    #[test]
    fn the_score_falls_toward_the_edge_of_the_reach_and_is_zero_beyond_it() {
        let (c, _) = fixture();
        let rest = at_goal(&c, 0.15);
        let slow = c.cfg.params.singularity_slow;
        // The head moved away from the base along its x, 5 cm at a time.
        let scores: Vec<f64> = (0..8)
            .map(|k| {
                let head = Isometry3::translation(0.05 * k as f64, 0.0, 0.0) * head_rest();
                c.reach(&rest, &head).score(slow)
            })
            .collect();
        assert!(scores[0] > 0.0, "{scores:?}");
        assert_eq!(*scores.last().unwrap(), 0.0, "{scores:?}");
        // Once refused, refused further out.
        let first_zero = scores.iter().position(|s| *s == 0.0).unwrap();
        assert!(scores[first_zero..].iter().all(|s| *s == 0.0), "{scores:?}");
    }
}
