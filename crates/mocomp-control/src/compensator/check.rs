//! Limit, filter and check the command: the rate limits ([`super::command`]), then the safety
//! filter (a command whose coil would come closer to the predicted head than required is moved
//! back along the approach axis by the deficit, [`crate::safety`]), then the collision checks on
//! the motion (links, the coil's contact tolerance, the approach rule), each answered by its
//! reaction: the coil gives way to a head that comes into it; anything else is refused and the
//! arm decelerates on its last command.

use super::clearance::Site;
use super::command::Saved;
use super::{Compensator, CycleRecord, Event, Mode, Plan};
use crate::safety::{backed_off, standoff_remembering};
use crate::supervisor::{Reaction, Reason, reaction};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_kin::Selection;

/// Corrections of one command by the safety filter (each re-solves IK and the limits).
const FILTER_PASSES: usize = 2;

/// Point `k` of 0..=4 along link `i` (from frame `i - 1` to frame `i`) of the arm's `frames`:
/// where the link capsules are checked against the head.
pub(super) fn link_point(frames: &[Isometry3<f64>; 7], i: usize, k: u32) -> Point3<f64> {
    let a = frames[i - 1].translation.vector;
    let b = frames[i].translation.vector;
    Point3::from(a + (b - a) * (f64::from(k) / 4.0))
}

impl Compensator {
    /// The coil at joints `q` seen from the head at `base_from_head`.
    pub(super) fn head_from_coil_at(
        &self,
        q: &[f64; 6],
        base_from_head: &Isometry3<f64>,
    ) -> Isometry3<f64> {
        base_from_head.inverse() * self.arm.fk_flange(q) * self.cfg.flange_from_coil
    }

    /// The coil's nearest distance to the head (its face rim, centre and back), m.
    pub(super) fn coil_distance(&self, head_from_coil: &Isometry3<f64>) -> f64 {
        self.cfg.coil.distance(&self.cfg.head, head_from_coil)
    }

    /// The rate limits on `desired`, then the safety filter while following the head: returns
    /// the state before the limits ran (what a correction starts again from) and the command.
    pub(super) fn limit_and_filter(
        &mut self,
        desired: &[f64; 6],
        speed_fraction: f64,
        base_from_head: Option<&Isometry3<f64>>,
        required: f64,
        rec: &mut CycleRecord,
    ) -> (Saved, [f64; 6]) {
        let saved = self.cmd.save();
        self.cmd.giving_way = matches!(self.mode, Mode::Retreating(_));
        let mut q_next = self.limit(desired, speed_fraction);
        if let Some(bh) = base_from_head
            && matches!(self.mode, Mode::Tracking | Mode::Retreating(_))
        {
            let max_standoff = self.cfg.params.max_standoff_m;
            let mut extra = 0.0;
            for _ in 0..FILTER_PASSES {
                let coil = self.head_from_coil_at(&q_next, bh);
                let deficit = self.clearance.at(Site::Filter, |memory| {
                    standoff_remembering(
                        &self.cfg.head,
                        &self.cfg.coil,
                        &coil,
                        required,
                        max_standoff,
                        memory,
                    )
                });
                if deficit <= 0.0 {
                    break;
                }
                extra += deficit;
                match self.retarget(bh, extra, saved, desired, speed_fraction) {
                    Some(q) => q_next = q,
                    None => break,
                }
            }
            rec.filtered_m = extra;
        }
        (saved, q_next)
    }

    /// The rate limits on `desired` with this cycle's state (see
    /// [`super::command::CommandState::limit`]).
    fn limit(&mut self, desired: &[f64; 6], speed_fraction: f64) -> [f64; 6] {
        self.cmd.limit(
            &self.arm,
            &self.cfg.params,
            self.period,
            desired,
            speed_fraction,
            // While following the goal; a retreat, a path or a hold keeps to its joints' own
            // limits (giving way is never traded for dose).
            (self.cfg.params.weigh_by_dose && self.mode == Mode::Tracking)
                .then_some(&self.cfg.flange_from_coil),
        )
    }

    /// Re-solves this cycle's command for the current standoff plus `extra` (m), from the state
    /// before the limits ran (`saved`), so a correction is limited like any command. The
    /// target's speed stays the uncorrected target's (`nominal`): a correction is not a motion to
    /// keep. `None` when the IK fails.
    fn retarget(
        &mut self,
        base_from_head: &Isometry3<f64>,
        extra: f64,
        saved: Saved,
        nominal: &[f64; 6],
        speed_fraction: f64,
    ) -> Option<[f64; 6]> {
        let s = &self.standoff;
        let d = (s.distance - s.press + extra).min(self.cfg.params.max_standoff_m);
        let target = base_from_head * backed_off(&s.anchor, d) * self.coil_from_flange;
        let c = self
            .arm
            .ik_closest(
                &target,
                &saved.q,
                &Selection::tracking(self.cfg.params.joint_margin_rad),
            )
            .ok()?;
        self.cmd.restore(saved);
        let q = self.limit(&c.joints, speed_fraction);
        self.cmd.last_desired = Some(*nominal);
        Some(q)
    }

    /// The collision checks on the command `q_next` (from `saved`), for the head at
    /// `base_from_head`, each answered by its reaction: a head that comes into the coil makes it
    /// give way along its axis (from the goal when following it, else from where the coil is),
    /// anything else refuses the command. Returns the command to send.
    pub(super) fn check_phase(
        &mut self,
        base_from_head: Option<&Isometry3<f64>>,
        saved: Saved,
        desired: &[f64; 6],
        speed_fraction: f64,
        q_next: [f64; 6],
        event: &mut Option<Event>,
    ) -> [f64; 6] {
        let Some(bh) = base_from_head else {
            return q_next;
        };
        let prev = self.head.last_head.unwrap_or(*bh);
        self.head.last_head = Some(*bh);
        let approach_rule = !matches!(self.mode, Mode::Tracking | Mode::Retreating(_));
        let Some(r) = self.check_motion(&saved.q, &q_next, &prev, bh, approach_rule) else {
            return q_next;
        };
        if reaction(&r) == Reaction::Retreat
            && let Some(q) = self.give_way_now(bh, saved, desired, speed_fraction)
        {
            self.clear_since = None;
            *event = self.transition(Mode::Retreating(r)).or(*event);
            return q;
        }
        // Refuse: decelerate along the last command instead.
        self.cmd.restore(saved);
        let hold = self.cmd.stand_still();
        let q = self.limit(&hold, speed_fraction);
        self.clear_since = None;
        // A hold outranks a resume decided earlier in the same cycle. A coil refused near the
        // head goes round by the shell when it resumes, never straight on.
        self.approach.path = None;
        self.approach.replan |= matches!(r, Reason::CoilCollision(_) | Reason::OffApproachAxis(_));
        *event = self.transition(Mode::Holding(r)).or(*event);
        q
    }

    /// The head comes into the coil: back off now along the coil's axis, the most the limits
    /// allow this cycle, even if that is not yet clear of the head (holding instead would let
    /// the head push in further); only a link the retreat would bring into the head stops it
    /// (`None`).
    fn give_way_now(
        &mut self,
        bh: &Isometry3<f64>,
        saved: Saved,
        desired: &[f64; 6],
        speed_fraction: f64,
    ) -> Option<[f64; 6]> {
        if !matches!(self.mode, Mode::Tracking | Mode::Retreating(_)) {
            self.standoff.anchor = self.head_from_coil_at(&saved.q, bh);
            self.standoff.distance = 0.0;
            self.approach.path = None;
        }
        self.standoff.distance = self
            .standoff
            .distance
            .max(self.cfg.params.retreat_distance_m);
        self.cmd.giving_way = true;
        let q = self.retarget(bh, 0.0, saved, desired, speed_fraction)?;
        (!matches!(
            self.check_motion(&saved.q, &q, bh, bh, false),
            Some(Reason::LinkCollision(..))
        ))
        .then_some(q)
    }

    /// Checks the motion from `q_prev` (commanded while the head was at `head_prev`) to `q` (for
    /// the head at `head_now`), both `base_from_head`: links keep their clearance, the coil never
    /// enters the head, and near the head the coil may get closer only along its approach axis.
    ///
    /// "Closer" means closer than before in both head poses: following a head that moves away
    /// is not approaching it, and a head that moves into a still coil is not the robot's doing.
    /// Moving away or sideways is always allowed, so a hold never locks itself in.
    pub fn collision(
        &self,
        q_prev: &[f64; 6],
        q: &[f64; 6],
        head_prev: &Isometry3<f64>,
        head_now: &Isometry3<f64>,
    ) -> Option<Reason> {
        self.check_motion(q_prev, q, head_prev, head_now, true)
    }

    /// [`Self::collision`], with the approach rule optional: a coil that follows the head near
    /// its goal deviates sideways by its tracking error, which is no approach from the side (its
    /// clearance is the safety filter's, on the whole coil model).
    fn check_motion(
        &self,
        q_prev: &[f64; 6],
        q: &[f64; 6],
        head_prev: &Isometry3<f64>,
        head_now: &Isometry3<f64>,
        approach_rule: bool,
    ) -> Option<Reason> {
        let now_from_base = head_now.inverse();
        let prev_from_base = head_prev.inverse();
        if let Some(r) = self.link_check(q_prev, q, &now_from_base, &prev_from_base) {
            return Some(r);
        }
        // Both flanges by the same computation: a command that does not move must compare equal
        // to itself to the last bit, or a hold would refuse to stay where it is.
        let prev_flange = self.arm.fk_flange(q_prev);
        let flange = self.arm.fk_flange(q);
        let coil_now = now_from_base * flange * self.cfg.flange_from_coil;
        let coil_prev_now = now_from_base * prev_flange * self.cfg.flange_from_coil;
        let coil_prev_prev = prev_from_base * prev_flange * self.cfg.flange_from_coil;
        let p = &self.cfg.params;
        let deepest = if self.in_contact_mode() {
            -p.contact_max_press_m - p.coil_contact_tolerance_m
        } else {
            p.coil_min_distance_m - p.coil_contact_tolerance_m
        };
        let nearest = self.clearance.at(Site::Collision, |memory| {
            self.cfg
                .coil
                .distance_below_remembering(&self.cfg.head, &coil_now, deepest, memory)
        });
        if nearest < deepest
            && nearest
                < self
                    .coil_distance(&coil_prev_now)
                    .min(self.coil_distance(&coil_prev_prev))
        {
            return Some(Reason::CoilCollision(nearest));
        }
        if approach_rule {
            return self.approach_check(
                coil_now.translation.vector,
                coil_prev_now.translation.vector,
                coil_prev_prev.translation.vector,
            );
        }
        None
    }

    /// The links up to wrist 2 (wrist 3 and the flange are inside the coil's model) keep their
    /// clearance, or move no closer than they were.
    fn link_check(
        &self,
        q_prev: &[f64; 6],
        q: &[f64; 6],
        now_from_base: &Isometry3<f64>,
        prev_from_base: &Isometry3<f64>,
    ) -> Option<Reason> {
        let frames = self.arm.link_frames(q);
        // The previous command's links are needed only near the head (rare).
        let mut prev_frames: Option<[Isometry3<f64>; 7]> = None;
        let head = &self.cfg.head;
        let (radius, clearance) = (
            self.cfg.params.link_radius_m,
            self.cfg.params.link_clearance_m,
        );
        for i in 1..6 {
            for k in 0..=4 {
                let p = link_point(&frames, i, k);
                let d = head.distance_below(&(now_from_base * p), clearance + radius) - radius;
                if d < clearance {
                    let pf = prev_frames.get_or_insert_with(|| self.arm.link_frames(q_prev));
                    let p0 = link_point(pf, i, k);
                    let d0 = head
                        .distance(&(now_from_base * p0))
                        .min(head.distance(&(prev_from_base * p0)))
                        - radius;
                    if d < d0 {
                        return Some(Reason::LinkCollision(i, d));
                    }
                }
            }
        }
        None
    }

    /// The approach rule on the coil's centre (`centre`, and before: `p1` and `p2` in the two
    /// head poses): near the head the coil moves closer only along an approach axis, the
    /// goal's, or on a path the axis it set out along (leaving one target for its neighbour,
    /// the coil backs out along its own axis, which is off the new goal's).
    fn approach_check(
        &self,
        centre: Vector3<f64>,
        p1: Vector3<f64>,
        p2: Vector3<f64>,
    ) -> Option<Reason> {
        let head = &self.cfg.head;
        let zone = self.cfg.params.approach_zone_m;
        let d = head.distance_below(&Point3::from(centre), zone);
        let d_prev = || {
            head.distance(&Point3::from(p1))
                .min(head.distance(&Point3::from(p2)))
        };
        // Not nearer the head than before, or outside the zone: any direction is allowed.
        let approaching = d < zone && d < d_prev() - 1e-6;
        if !approaching {
            return None;
        }
        let axis_of = |g: &Isometry3<f64>| (g.translation.vector, g.rotation * Vector3::z());
        let axes = [
            Some(axis_of(&self.cfg.head_from_coil_goal)),
            self.approach
                .path
                .filter(|_| self.mode == Mode::Approaching)
                .and_then(|p| match p {
                    Plan::Shell(p) => Some(axis_of(p.start())),
                    Plan::Transit(_) => None,
                }),
        ];
        let lateral_of = |c: Vector3<f64>| {
            axes.iter()
                .flatten()
                .map(|(o, axis)| {
                    let rel = c - o;
                    (rel - axis * rel.dot(axis)).norm()
                })
                .fold(f64::INFINITY, f64::min)
        };
        let lateral = lateral_of(centre);
        // Closer to the head only on the approach axis, or while converging onto it.
        (lateral > self.cfg.params.approach_tolerance_m
            && lateral >= lateral_of(p1).max(lateral_of(p2)))
        .then_some(Reason::OffApproachAxis(lateral))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::super::tests::{at_goal, fixture};
    use super::*;
    use mocomp_testkit::scene::head_rest;

    #[test]
    fn a_command_into_the_head_is_a_coil_collision_and_moving_out_is_not() {
        let (c, _) = fixture();
        let bh = head_rest();
        let out = at_goal(&c, 0.01);
        // 3 cm in along the axis from the goal: into the scalp.
        let deep = at_goal(&c, -0.03);
        assert!(matches!(
            c.check_motion(&out, &deep, &bh, &bh, false),
            Some(Reason::CoilCollision(d)) if d < 0.0
        ));
        assert_eq!(c.check_motion(&deep, &out, &bh, &bh, false), None);
        // Standing still is never refused, wherever the coil is.
        assert_eq!(c.check_motion(&deep, &deep, &bh, &bh, true), None);
    }

    #[test]
    fn near_the_head_the_coil_comes_closer_only_along_its_axis() {
        let (c, _) = fixture();
        let bh = head_rest();
        let goal = c.cfg.head_from_coil_goal;
        let coil_at = |offset: Vector3<f64>| {
            let head_from_coil = Isometry3::from_parts(
                (goal.translation.vector + goal.rotation * offset).into(),
                goal.rotation,
            );
            c.arm
                .ik_closest(
                    &(bh * head_from_coil * c.coil_from_flange),
                    &at_goal(&c, 0.0),
                    &Selection::tracking(0.05),
                )
                .unwrap()
                .joints
        };
        // 2 cm to the side and 1 cm out, moving in towards the head: off the axis.
        let (from, to) = (
            coil_at(Vector3::new(0.02, 0.0, -0.012)),
            coil_at(Vector3::new(0.02, 0.0, -0.008)),
        );
        assert!(matches!(
            c.check_motion(&from, &to, &bh, &bh, true),
            Some(Reason::OffApproachAxis(l)) if l > 0.019
        ));
        // The same move on the axis is allowed, and so is the side one without the rule.
        let (from_axis, to_axis) = (
            coil_at(Vector3::new(0.0, 0.0, -0.012)),
            coil_at(Vector3::new(0.0, 0.0, -0.008)),
        );
        assert_eq!(c.check_motion(&from_axis, &to_axis, &bh, &bh, true), None);
        assert_eq!(c.check_motion(&from, &to, &bh, &bh, false), None);
    }

    #[test]
    fn the_filter_moves_a_command_too_close_back_along_the_axis() {
        let (mut c, mut robot) = fixture();
        let bh = head_rest();
        robot.tick(0.0);
        let q = at_goal(&c, 0.0);
        robot.state.actual_q = q;
        c.cmd
            .step_time(&robot.state, c.period, c.cfg.params.robot_stale_s);
        c.mode = Mode::Tracking;
        let clear_at_goal = c.coil_distance(&c.head_from_coil_at(&q, &bh));
        let required = clear_at_goal + 0.0005;
        let mut rec = CycleRecord::new(0.0, c.mode, c.cmd.q);
        let (_, mut q_next) = c.limit_and_filter(&q, 1.0, Some(&bh), required, &mut rec);
        assert!(rec.filtered_m > 0.0004, "{}", rec.filtered_m);
        // Limited like any command: out at once, by the deficit within a few cycles.
        let mut after = c.coil_distance(&c.head_from_coil_at(&q_next, &bh));
        assert!(after > clear_at_goal, "{after} vs {clear_at_goal}");
        for k in 1..100 {
            c.cmd.q = q_next;
            robot.tick(k as f64 * c.period);
            c.cmd
                .step_time(&robot.state, c.period, c.cfg.params.robot_stale_s);
            (_, q_next) = c.limit_and_filter(&q, 1.0, Some(&bh), required, &mut rec);
            after = c.coil_distance(&c.head_from_coil_at(&q_next, &bh));
        }
        // Within a tenth of a millimetre (a lasting requirement is the standoff's, which backs
        // the goal itself off).
        assert!(after > required - 1e-4, "{after} vs {required}");
        // Holding, the filter does not run (a hold gives way by its own rule).
        c.mode = Mode::Holding(Reason::Operator);
        let mut rec = CycleRecord::new(0.0, c.mode, c.cmd.q);
        let q = c.cmd.q;
        c.limit_and_filter(&q, 1.0, Some(&bh), required, &mut rec);
        assert_eq!(rec.filtered_m, 0.0);
    }
}
