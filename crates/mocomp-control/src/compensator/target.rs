//! Target: where this cycle's command should go, for the reaction the supervisor decided.
//!
//! - the standoff the goal is backed off by along its approach axis (the safety filter's and a
//!   retreat's; it grows at once and shrinks softly), and contact mode's press into the scalp
//!   (the admittance);
//! - the goal's joints on the current branch (or a fault of its own: unreachable, singular);
//! - the mode machine's choices: follow the goal, wait out `resume_after_s`, come back by a
//!   planned path ([`super::plan`]), retreat, hold — a held coil still giving way to a head that
//!   comes closer than the filter requires.

use super::clearance::Site;
use super::plan::ShellStep;
use super::sense::HeadEstimate;
use super::{Compensator, CycleRecord, Event, Mode, Plan};
use crate::force::{admittance_step, is_force_reason};
use crate::safety::{backed_off, standoff_remembering};
use crate::supervisor::{Decision, Reaction, Reason};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::{BranchPolicy, Selection};

/// Deceleration of a standoff shrinking back to the goal, m/s².
const STANDOFF_LANDING_M_S2: f64 = 1.0;
/// An axial force above this means the coil touches the scalp, N (well above a sensor's noise
/// after the filter).
const TOUCH_N: f64 = 0.5;
/// How much closer than the safety filter's clearance a head must come to a held coil for it
/// to give way, m: more than the clearance's cycle-to-cycle noise.
const GIVE_WAY_DEADBAND_M: f64 = 0.5e-3;

/// Where along the approach axis the coil is kept.
#[derive(Debug, Clone)]
pub(super) struct StandoffState {
    /// The standoff along the approach axis the anchor is backed off by, m.
    pub(super) distance: f64,
    /// The coil pose (`head_from_coil`) the standoff backs off from: the goal, or where the coil
    /// was when it had to give way away from the goal (approaching, holding).
    pub(super) anchor: Isometry3<f64>,
    /// Contact mode's press from the goal along the approach axis, m.
    pub(super) press: f64,
    /// Coming back from a force retreat: the standoff shrinks at the admittance's pace.
    pub(super) force_landing: bool,
    /// When a held coil last had to give way to the head, s (loop time).
    pub(super) gave_way_at: f64,
}

impl StandoffState {
    /// On the goal `head_from_coil_goal`, no standoff.
    pub(super) fn new(head_from_coil_goal: Isometry3<f64>) -> Self {
        Self {
            distance: 0.0,
            anchor: head_from_coil_goal,
            press: 0.0,
            force_landing: false,
            gave_way_at: f64::NEG_INFINITY,
        }
    }
}

/// The goal's joints and their singularity margin.
pub(super) type GoalJoints = ([f64; 6], f64);

impl Compensator {
    /// The flange target for the head at `base_from_head`: the anchor (usually the goal),
    /// backed off by the current standoff.
    pub(super) fn standoff_target(&self, base_from_head: &Isometry3<f64>) -> Isometry3<f64> {
        let s = &self.standoff;
        base_from_head * backed_off(&s.anchor, s.distance - s.press) * self.coil_from_flange
    }

    /// Contact mode's press along the axis: the admittance while following the goal, none
    /// otherwise.
    pub(super) fn contact_press(&mut self, react: Reaction) -> f64 {
        self.standoff.press = if self.in_contact_mode() && react == Reaction::Track {
            let p = &self.cfg.params;
            let max_press = self.goal.check.unwrap_or(0.0) + p.contact_max_press_m;
            admittance_step(
                self.standoff.press,
                self.force.axial_n,
                self.cmd.dt,
                p,
                max_press,
            )
        } else {
            0.0
        };
        self.standoff.press
    }

    /// The standoff the goal needs for the head at `base_from_head`: the filter's for the
    /// `required` clearance, and the retreat's while retreating. It grows at once and shrinks
    /// at `standoff_return_m_s`, landing softly; with force sensing, a coil that touches stops
    /// coming in and one that presses backs off at the admittance's pace.
    pub(super) fn update_standoff(
        &mut self,
        base_from_head: &Isometry3<f64>,
        required: f64,
        react: Reaction,
        rec: &mut CycleRecord,
    ) {
        let p = &self.cfg.params;
        // The goal's own clearance is fixed (the goal check's); only a larger requirement asks
        // for a standoff.
        let goal_clear = self.goal.check.unwrap_or(f64::NEG_INFINITY);
        let mut need = if required <= goal_clear {
            0.0
        } else {
            self.clearance.at(Site::Goal, |memory| {
                standoff_remembering(
                    &self.cfg.head,
                    &self.cfg.coil,
                    &self.cfg.head_from_coil_goal,
                    required,
                    p.max_standoff_m,
                    memory,
                )
            })
        };
        if react == Reaction::Retreat || matches!(self.mode, Mode::Retreating(_)) {
            need = need.max(p.retreat_distance_m);
        }
        let s = &mut self.standoff;
        // Coming back in, the coil lands softly: its speed falls with the standoff left, so it
        // stops on the goal instead of overshooting into the scalp.
        let mut back = p
            .standoff_return_m_s
            .min((2.0 * STANDOFF_LANDING_M_S2 * s.distance).sqrt());
        let mut relief = 0.0;
        if p.force_sensing {
            // A coil that meets the scalp before its goal (the head model or the calibration is
            // off by more than the goal's standoff) stops coming in where it touches lightly,
            // and one pressing harder backs off to that light touch at the admittance's pace
            // (contact mode presses by its own admittance instead); back from a force retreat
            // it comes in at that pace too.
            let axial = self.force.axial_n;
            let contact_mode = p.contact_mode && self.mode == Mode::Tracking;
            if axial > p.contact_force_n {
                back = 0.0;
                if !contact_mode {
                    relief = ((axial - p.contact_force_n) / p.contact_damping_n_s_m)
                        .min(p.retreat_tcp_speed_m_s);
                    s.force_landing = true;
                }
            } else if s.force_landing {
                // Clear of the scalp at the admittance's top speed, touching by its law.
                let touching = axial > TOUCH_N;
                back = back.min(if touching {
                    (p.contact_force_n - axial) / p.contact_damping_n_s_m
                } else {
                    p.contact_speed_m_s
                });
            }
        }
        let dt = self.cmd.dt;
        s.distance = need.max(s.distance - back * dt + relief * dt);
        if s.distance <= need {
            s.force_landing = false;
        }
        rec.standoff_m = s.distance;
        rec.goal = Some(base_from_head * self.cfg.head_from_coil_goal * self.coil_from_flange);
    }

    /// The goal's joints when the reaction follows the head (track, retreat) and the head is
    /// known: on the current branch while following, on any branch otherwise (a transit gets
    /// there). `Err`: the goal's own rule that fired (unreachable, singular).
    pub(super) fn goal_joints(
        &self,
        react: Reaction,
        base_from_head: Option<&Isometry3<f64>>,
    ) -> Result<Option<GoalJoints>, Reason> {
        let (Reaction::Track | Reaction::Retreat, Some(bh)) = (react, base_from_head) else {
            return Ok(None);
        };
        let target = self.standoff_target(bh);
        let margin = self.cfg.params.joint_margin_rad;
        let solved = self
            .arm
            .ik_closest(&target, &self.cmd.q, &Selection::tracking(margin))
            .or_else(|e| {
                // Not yet following (holding, faulted, on the way): a goal on another branch is
                // reached by a transit, which the planner decides; following, the loop never
                // changes branch.
                if matches!(self.mode, Mode::Tracking | Mode::Retreating(_)) {
                    Err(e)
                } else {
                    let any = Selection {
                        branch: BranchPolicy::Any,
                        ..Selection::tracking(margin)
                    };
                    self.arm.ik_closest(&target, &self.cmd.q, &any)
                }
            });
        let c = solved.map_err(|_| Reason::Unreachable)?;
        let m = self.arm.singularity_margin(&c.joints);
        if m < self.cfg.params.singularity_hold {
            return Err(Reason::Singular(m));
        }
        Ok(Some((c.joints, m)))
    }

    /// The target's speed along this cycle's prediction, rad/s: the goal's joints one controller
    /// period earlier on the same predicted path, solved beside this cycle's. Only while the
    /// command follows the goal itself (`desired` is its joints, tracking or retreating from
    /// the head); a path, a hold and a give-way have speeds of their own.
    pub(super) fn target_speed(
        &self,
        goal_q: Option<GoalJoints>,
        desired: &[f64; 6],
        head: &HeadEstimate,
    ) -> Option<[f64; 6]> {
        let (q, _) = goal_q?;
        if q != *desired || !matches!(self.mode, Mode::Tracking | Mode::Retreating(_)) {
            return None;
        }
        let before = self.standoff_target(head.base_from_head_before.as_ref()?);
        let margin = self.cfg.params.joint_margin_rad;
        let c = self
            .arm
            .ik_closest(&before, &q, &Selection::tracking(margin))
            .ok()?;
        Some(std::array::from_fn(|j| (q[j] - c.joints[j]) / self.period))
    }

    /// This cycle's target joints and speed fraction for the supervisor's `decision`, with the
    /// goal's joints (`goal_q`) and the head; the mode changes it makes add their event.
    pub(super) fn target(
        &mut self,
        now: f64,
        decision: Decision,
        goal_q: Option<GoalJoints>,
        head: &HeadEstimate,
        rec: &mut CycleRecord,
        event: &mut Option<Event>,
    ) -> ([f64; 6], f64) {
        let mut speed_fraction = self.cfg.params.speed_fraction;
        let desired = match (
            decision.reaction,
            decision.reason,
            goal_q,
            head.base_from_head,
        ) {
            (Reaction::Retreat, Some(r), Some((q, _)), Some(_)) => {
                // Keep following the head from the standoff.
                self.clear_since = None;
                self.approach.path = None;
                *event = event.or(self.transition(Mode::Retreating(r)));
                q
            }
            (Reaction::Track, _, Some((q, margin)), Some(bh)) => {
                let q = self.track_target(now, q, &bh, rec, event);
                if matches!(q, TrackTarget::Goal(_)) && margin < self.cfg.params.singularity_slow {
                    speed_fraction *= (margin / self.cfg.params.singularity_slow).max(0.1);
                }
                q.joints()
            }
            (react, r, _, bh) => {
                // Hold (Plan included: hold now, go by a path once clear).
                if react == Reaction::Plan {
                    self.approach.replan = true;
                }
                self.clear_since = None;
                self.approach.path = None;
                match bh.and_then(|bh| self.give_way_in_hold(now, &bh, head.required)) {
                    Some((q, why)) => {
                        *event = event.or(self.transition(Mode::Retreating(why)));
                        q
                    }
                    None => {
                        let why = r.unwrap_or(Reason::NoTracker);
                        *event = event.or(self.transition(Mode::Holding(why)));
                        self.cmd.stand_still()
                    }
                }
            }
        };
        (desired, speed_fraction)
    }

    /// Nothing fired and the goal's joints are `q`: wait out the resume time, come back by a
    /// path when the coil is off its goal, follow the path, or follow the goal.
    fn track_target(
        &mut self,
        now: f64,
        q: [f64; 6],
        base_from_head: &Isometry3<f64>,
        rec: &mut CycleRecord,
        event: &mut Option<Event>,
    ) -> TrackTarget {
        let since = *self.clear_since.get_or_insert(now);
        let p = &self.cfg.params;
        let waiting = match self.mode {
            Mode::Holding(_) | Mode::Faulted(_) => now - since < p.resume_after_s,
            Mode::Retreating(r) if is_force_reason(&r) => now - since < p.contact_resume_s,
            Mode::Retreating(_) => now - since < p.retreat_resume_s,
            Mode::Tracking | Mode::Approaching => false,
        };
        if waiting {
            // A retreat keeps following from its standoff; a hold stays.
            return if matches!(self.mode, Mode::Retreating(_)) {
                TrackTarget::Waiting(q)
            } else {
                TrackTarget::Waiting(self.cmd.stand_still())
            };
        }
        // A new goal while approaching drops the path: plan again, never go straight.
        let refused = if self.mode != Mode::Approaching || self.approach.path.is_none() {
            self.resume(base_from_head, event)
        } else {
            None
        };
        match (refused, self.mode, self.approach.path) {
            (Some(r), _, _) => {
                self.clear_since = None;
                *event = event.or(self.transition(Mode::Holding(r)));
                TrackTarget::Waiting(self.cmd.stand_still())
            }
            (None, Mode::Approaching, Some(Plan::Transit(t))) => {
                TrackTarget::Path(self.transit_step(&t))
            }
            (None, Mode::Approaching, Some(Plan::Shell(path))) => {
                match self.shell_step(&path, base_from_head, rec) {
                    ShellStep::Unreachable => {
                        self.clear_since = None;
                        *event = event.or(self.transition(Mode::Holding(Reason::Unreachable)));
                        TrackTarget::Waiting(self.cmd.stand_still())
                    }
                    ShellStep::Arrived(q) => {
                        // At the goal: hand over to tracking.
                        *event = event.or(self.transition(Mode::Tracking));
                        TrackTarget::Path(q)
                    }
                    ShellStep::On(q) => TrackTarget::Path(q),
                }
            }
            _ => TrackTarget::Goal(q),
        }
    }

    /// Resuming after the resume time: straight on to the goal when the coil is near it (or
    /// coming back from a retreat on its axis), else by a planned path (approaching). Returns
    /// the planner's refusal.
    fn resume(
        &mut self,
        base_from_head: &Isometry3<f64>,
        event: &mut Option<Event>,
    ) -> Option<Reason> {
        let from_retreat = matches!(self.mode, Mode::Retreating(_));
        if self.standoff.anchor != self.cfg.head_from_coil_goal {
            // The coil gave way away from the goal (approaching, holding): back to the goal by
            // a path, never straight in from the side.
            self.standoff.anchor = self.cfg.head_from_coil_goal;
            self.standoff.distance = 0.0;
            self.approach.replan = true;
        }
        let p = &self.cfg.params;
        let cmd = self.arm.fk_flange(&self.cmd.q);
        let target = self.standoff_target(base_from_head);
        let far = (cmd.translation.vector - target.translation.vector).norm() > p.servo_deviation_m
            || cmd.rotation.angle_to(&target.rotation) > p.plan_rotation_rad;
        // Back from a retreat on the goal's axis the coil comes straight in.
        let by_path = (far && !from_retreat && self.mode != Mode::Tracking) || self.approach.replan;
        if !by_path {
            *event = event.or(self.transition(Mode::Tracking));
            return None;
        }
        match self.plan(base_from_head) {
            Ok(plan) => {
                self.take_plan(plan);
                let resumed = self.transition(Mode::Approaching);
                *event = event.or(match plan {
                    Plan::Transit(t) => Some(Event::Transit(t.length())),
                    Plan::Shell(_) => resumed,
                });
                None
            }
            Err(r) => Some(r),
        }
    }

    /// A held coil with the head in view gives way when the head comes closer than `required`
    /// (the safety filter's clearance): it backs off `retreat_distance_m` along its axis from
    /// where it is, following the head, until the head has stayed clear for `retreat_resume_s`;
    /// then it holds again where it got to. Returns the target joints and the reason while it
    /// gives way; `None`: hold.
    fn give_way_in_hold(
        &mut self,
        now: f64,
        base_from_head: &Isometry3<f64>,
        required: f64,
    ) -> Option<([f64; 6], Reason)> {
        let p = &self.cfg.params;
        let here = self.head_from_coil_at(&self.cmd.q, base_from_head);
        let clearance = self.coil_distance(&here);
        let s = &mut self.standoff;
        let giving_way =
            matches!(self.mode, Mode::Retreating(_)) && now - s.gave_way_at < p.retreat_resume_s;
        // A coil that has given way rests where the safety filter holds it, at `required`, which
        // the prediction's uncertainty moves by tenths of a millimetre from cycle to cycle: only
        // a head that comes closer by more than that gives way (again), or the coil would give
        // way for ever and never hold. The filter still keeps `required` on every command.
        if clearance < required - GIVE_WAY_DEADBAND_M {
            if !giving_way {
                s.anchor = here;
                s.distance = 0.0;
            }
            s.gave_way_at = now;
        } else if !giving_way {
            return None;
        }
        s.distance = s.distance.max(p.retreat_distance_m);
        let why = match self.mode {
            Mode::Retreating(r) if giving_way => r,
            _ => Reason::CoilCollision(clearance),
        };
        self.arm
            .ik_closest(
                &self.standoff_target(base_from_head),
                &self.cmd.q,
                &Selection::tracking(p.joint_margin_rad),
            )
            .ok()
            .map(|c| (c.joints, why))
    }
}

/// What the tracking branch of the target gives.
#[derive(Debug, Clone, Copy, PartialEq)]
enum TrackTarget {
    /// Waiting (a hold standing, a retreat following from its standoff) or refused.
    Waiting([f64; 6]),
    /// A step along the planned path.
    Path([f64; 6]),
    /// The goal itself: slowed near a singularity.
    Goal([f64; 6]),
}

impl TrackTarget {
    fn joints(self) -> [f64; 6] {
        match self {
            Self::Waiting(q) | Self::Path(q) | Self::Goal(q) => q,
        }
    }
}
