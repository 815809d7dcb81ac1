//! The compensation loop, one cycle at the robot's rate, on an injectable clock. No allocation,
//! no lock, no logging: the caller gets a [`CycleRecord`] (`Copy`) to queue for a logger.
//!
//! [`Compensator::cycle`] runs these phases in order; each is a function of its own file, and
//! each phase's state is a struct that phase owns:
//!
//! | phase | what it does | where |
//! |---|---|---|
//! | sense | the newest tracker sample into the head estimate (outliers and old samples refused) | [`sense`]: `HeadState::take_sample` |
//! | rules: robot | a fault stops the arm and ends the cycle (latched until re-armed); free-drive too | [`robot`]: `Compensator::robot_phase` |
//! | rules: tracker, force | their reasons; a dropout coasts | [`sense`]: `tracker_phase`, `force_phase` |
//! | sense: head | the head where it will be when the command acts, the clearance required then | [`sense`]: `head_estimate` |
//! | decide | one reason and its reaction, by the precedence beside the table | [`crate::supervisor::decide`] |
//! | target | standoff, contact press, the goal's joints; follow, wait, come back by a path, retreat or hold | [`target`]: `update_standoff`, `goal_joints`, `target`; paths in [`plan`] |
//! | limit and filter | rate and acceleration limits (what they cannot grant given up where it costs the dose least), the safety filter's push back along the axis | [`command`]: `CommandState::limit`, [`priorities`]; [`check`]: `limit_and_filter` |
//! | check | the motion's collision checks, each answered by its reaction (give way, refuse) | [`check`]: `check_phase` |
//! | command | `servo`, and the record | here: `command` |
//!
//! Every mode change goes through [`Compensator::transition`], which says which event a change
//! reports. The cycle's event is the first one raised, but a refusal by the checks reports its
//! own over an earlier resume.
//!
//! The goal is `base_from_flange = base_from_tracker · tracker_from_head · head_from_coil_goal ·
//! coil_from_flange`, backed off along the approach axis by the standoff the safety filter asks
//! for ([`crate::safety`]).

mod check;
mod clearance;
mod command;
mod held;
mod in_flight;
mod plan;
mod priorities;
pub mod reach;
mod record;
mod robot;
mod sense;
mod target;
#[cfg(test)]
mod tests;

use crate::config::{LoopConfig, LoopParams};
use crate::goal::{GoalError, check_goal};
use crate::planner::ShellPath;
pub use crate::supervisor::Reason;
use crate::supervisor::{Decision, RuleInputs, decide};
use crate::transit::JointPath;
use command::CommandState;
use mocomp_geom::PoseSource;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::Arm;
use mocomp_robot::Robot;
use plan::ApproachState;
pub use record::CycleRecord;
use robot::{FaultState, RobotStep};
pub use sense::HeadOracle;
use sense::{ForceState, HeadState};
use target::StandoffState;

/// What the loop is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// Following the goal with the servo (backed off along the approach axis by the standoff
    /// the safety filter asks for, usually none).
    Tracking,
    /// Following a planned path (retreat, shell, approach along the axis) to a goal far from the
    /// coil: at the start, after a hold, after a large head movement.
    Approaching,
    /// Following the head from `retreat_distance_m` back along the approach axis, for a reason
    /// (head too fast, head into the coil); comes back in when it has been clear for
    /// `resume_after_s`.
    Retreating(Reason),
    /// Holding the last safe command (decelerating to standstill) for a reason; resumes by
    /// itself when the reason has been clear for `resume_after_s`.
    Holding(Reason),
    /// The robot is stopped by a fault. A short gap in its state resumes by itself when the
    /// robot is healthy again; a fault the controller reports, or a long gap, latches
    /// ([`crate::supervisor::latches`]): the loop resumes only after the operator re-arms it
    /// ([`Compensator::rearm`]), from where the arm is, by a path.
    Faulted(Reason),
}

impl Mode {
    /// The kinds of mode, their reasons aside, in the order of [`Mode::kind`].
    pub const KINDS: [&'static str; 5] = [
        "tracking",
        "approaching",
        "holding",
        "faulted",
        "retreating",
    ];

    /// This mode's kind, its reason aside: an index into [`Mode::KINDS`] (for counts per mode
    /// and figures).
    pub fn kind(&self) -> usize {
        match self {
            Self::Tracking => 0,
            Self::Approaching => 1,
            Self::Holding(_) => 2,
            Self::Faulted(_) => 3,
            Self::Retreating(_) => 4,
        }
    }
}

/// Something worth logging, at most one per cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// The loop started holding (or stopped) for a reason.
    Hold(Reason),
    /// The loop started retreating for a reason.
    Retreat(Reason),
    /// The loop resumed tracking.
    Resume,
    /// A tracker sample was rejected as an outlier (implied m/s, rad/s).
    Outlier(f64, f64),
    /// The loop switched from approaching to tracking.
    Reached,
    /// A tracker dropout began; the loop coasts on the prediction (the newest sample's age, s).
    Coasting(f64),
    /// The loop resumed by a joint-space move to the goal's approach axis (a start far from the
    /// head, or on another IK branch): the largest joint's travel, rad.
    Transit(f64),
    /// The operator re-armed a latched fault (the controller had stopped the arm): the loop
    /// comes back, once the robot is healthy, from where the arm is, by a path.
    Rearmed,
}

/// The way to the goal the loop follows while approaching.
// Not boxed: a plan is made inside the cycle, and the cycle allocates nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Plan {
    /// Retreat, shell and approach in the head frame, on the current IK branch.
    Shell(ShellPath),
    /// A joint-space move in the base frame to the goal's approach axis, `transit_distance_m`
    /// back from the goal (possibly on another branch); a shell path follows it.
    Transit(JointPath),
}

/// The logged clearance is exact below this, a lower bound above (sparing the exact solve when
/// the coil is far), m: on a scalp, the most the sampled clearance knows exactly.
const CLEARANCE_EXACT_BELOW_M: f64 = mocomp_head::sampled::EXACT_BELOW_M;

/// The goal and what follows from it alone.
#[derive(Debug, Clone)]
struct GoalState {
    /// The goal's validity ([`crate::goal::check_goal`]) and its clearance, fixed with the
    /// configuration.
    check: Result<f64, GoalError>,
    /// Distance from the head marker to the coil at the goal, m: the lever that turns rotation
    /// uncertainty into position uncertainty at the coil.
    coil_lever: f64,
}

impl GoalState {
    fn new(cfg: &LoopConfig, head_from_coil: &Isometry3<f64>, params: &LoopParams) -> Self {
        Self {
            check: check_goal(
                &cfg.head,
                &cfg.coil,
                head_from_coil,
                params.goal_min_distance_m(),
            ),
            coil_lever: head_from_coil.translation.vector.norm(),
        }
    }
}

/// What the operator (or a front end) asked for.
#[derive(Debug, Clone, Copy, Default)]
struct OperatorState {
    /// The operator holds the loop ([`Compensator::set_operator_hold`]).
    hold: bool,
    /// The drift monitor's offset while the calibration is not valid.
    calibration_invalid: Option<(f64, f64)>,
    /// The operator guides the arm by hand.
    freedrive: bool,
}

/// The compensation loop's state, grouped by the phase that owns it.
#[derive(Debug, Clone)]
pub struct Compensator {
    cfg: LoopConfig,
    arm: Arm,
    coil_from_flange: Isometry3<f64>,
    period: f64,
    /// The mode machine: the mode, and since when its reason has been clear (for the resume
    /// times).
    mode: Mode,
    clear_since: Option<f64>,
    goal: GoalState,
    operator: OperatorState,
    /// Sense: the tracker's samples and the head estimate.
    head: HeadState,
    /// Sense: the force sensor.
    force: ForceState,
    /// Rules: the robot's fault and the stop sent for it.
    fault: FaultState,
    /// Target: the standoff along the approach axis, the anchor it backs off from, the press.
    standoff: StandoffState,
    /// Target: the planned way to the goal and the progress along it.
    approach: ApproachState,
    /// Limit and command: the setpoint, its speed, the controller time, the command delay.
    cmd: CommandState,
    /// What each per-cycle clearance query remembers from the last cycle.
    clearance: clearance::Memories,
}

impl Compensator {
    /// A loop for `arm` (its model fixes the speeds and limits) at the robot's `period_s`.
    pub fn new(cfg: LoopConfig, arm: Arm, period_s: f64) -> Self {
        let goal = GoalState::new(&cfg, &cfg.head_from_coil_goal, &cfg.params);
        Self {
            coil_from_flange: cfg.flange_from_coil.inverse(),
            head: HeadState::new(cfg.predictor),
            force: ForceState {
                monitor: crate::force::ForceMonitor::new(),
                range: mocomp_robot::ForceSource::range_n(arm.model()),
                axial_n: 0.0,
            },
            standoff: StandoffState::new(cfg.head_from_coil_goal),
            goal,
            cfg,
            arm,
            period: period_s,
            mode: Mode::Holding(Reason::NoTracker),
            clear_since: None,
            operator: OperatorState::default(),
            fault: FaultState::default(),
            approach: ApproachState::default(),
            cmd: CommandState::new(period_s),
            clearance: clearance::Memories::default(),
        }
    }

    /// The same loop with perfect knowledge of the head: `oracle`'s truth at the time each
    /// command acts instead of the prediction, and at the cycle's time for its errors, with no
    /// uncertainty. Everything else — the robot, its limits, the servo, the clearance, the
    /// rules — is the loop's own, so its error is the least any controller could make on this
    /// robot. The experiment's bound; never a real loop's.
    pub fn with_head_oracle(mut self, oracle: std::sync::Arc<dyn HeadOracle>) -> Self {
        self.head.oracle = Some(oracle);
        self
    }

    /// The operator's hold (`true`) or resume (`false`). A hold stops following the head where
    /// the coil is, with [`Reason::Operator`] (the supervisor's other rules outrank it); the coil
    /// still gives way to a head that comes closer than the safety filter requires. A resume
    /// comes back as after any hold: `resume_after_s`, then by a planned path when the coil is
    /// off its goal. Takes effect at the next cycle.
    pub fn set_operator_hold(&mut self, hold: bool) {
        self.operator.hold = hold;
    }

    /// The operator's re-arm after a latched fault (the console's or a front end's resume, once
    /// the robot's own recovery — reconnect, program restart, a protective stop unlocked — is
    /// done). Clears the latch; the robot rules still apply, so a fault that persists latches
    /// again at the next cycle. Comes back as after any fault: `resume_after_s` of a healthy
    /// robot, then from the arm's actual pose by a planned path. Returns whether a fault was
    /// latched.
    pub fn rearm(&mut self) -> bool {
        let was = self.fault.latched.take().is_some();
        if was {
            self.clear_since = None;
            self.fault.rearmed = true;
        }
        was
    }

    /// The latched fault that waits for the operator's re-arm, if any.
    pub fn latched(&self) -> Option<Reason> {
        self.fault.latched
    }

    /// The calibration no longer holds (the drift monitor's offset, m and rad): the loop holds
    /// with [`Reason::CalibrationInvalid`] until `None` (a new calibration). Faults, force rules
    /// and the coil's giving way outrank it; the operator's hold and the goal's check do not.
    pub fn set_calibration_invalid(&mut self, offset: Option<(f64, f64)>) {
        self.operator.calibration_invalid = offset;
    }

    /// Free-drive (`true`): from the next cycle the loop sends free-drive's keep-alive instead
    /// of a command, the arm yielding to the operator's hand, and holds with
    /// [`Reason::HandGuided`] (the head is still tracked, so the coil's pose on it can be taught).
    /// Its end (`false`) hands back to the loop from the arm's actual pose: the command starts
    /// there, and the goal is reached by a planned path, never straight from where the hand left
    /// the coil. A fault ends free-drive on the robot; the loop stays hand-guided until told.
    pub fn set_freedrive(&mut self, on: bool) {
        if self.operator.freedrive && !on {
            self.cmd.have = false;
            self.approach.path = None;
            self.approach.replan = true;
            self.standoff.anchor = self.cfg.head_from_coil_goal;
            self.standoff.distance = 0.0;
            self.clear_since = None;
        }
        self.operator.freedrive = on;
    }

    /// Whether the arm is hand-guided.
    pub fn freedrive(&self) -> bool {
        self.operator.freedrive
    }

    /// Whether the operator holds the loop.
    pub fn operator_hold(&self) -> bool {
        self.operator.hold
    }

    /// A new goal (`head_from_coil`), from the next cycle: taught while the loop runs. Refused,
    /// with the goal unchanged, when the goal check refuses it. The coil goes to it by a planned
    /// path once the loop follows again.
    pub fn set_goal(&mut self, head_from_coil: &Isometry3<f64>) -> Result<(), GoalError> {
        let goal = GoalState::new(&self.cfg, head_from_coil, &self.cfg.params);
        goal.check?;
        if self.standoff.anchor == self.cfg.head_from_coil_goal {
            self.standoff.anchor = *head_from_coil;
            self.standoff.distance = 0.0;
        }
        self.cfg.head_from_coil_goal = *head_from_coil;
        self.goal = goal;
        self.approach.path = None;
        self.approach.replan = true;
        Ok(())
    }

    /// New loop parameters, from the next cycle (the console's tuning). The goal's check, which
    /// depends on `coil_min_distance_m`, is redone; a goal the new parameters refuse holds the
    /// loop with its reason, as at start. The caller has validated them.
    pub fn set_params(&mut self, params: LoopParams) {
        self.cfg.params = params;
        self.goal.check = GoalState::new(&self.cfg, &self.cfg.head_from_coil_goal, &params).check;
    }

    /// The configuration.
    pub fn config(&self) -> &LoopConfig {
        &self.cfg
    }

    /// The current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The goal flange pose for a head pose (`tracker_from_head`).
    pub fn goal_for(&self, tracker_from_head: &Isometry3<f64>) -> Isometry3<f64> {
        self.cfg.base_from_tracker
            * tracker_from_head
            * self.cfg.head_from_coil_goal
            * self.coil_from_flange
    }

    /// The mode machine's one door: the loop enters `to` and gets the event the change reports
    /// (see [`transition_event`]).
    fn transition(&mut self, to: Mode) -> Option<Event> {
        let event = transition_event(self.mode, to);
        self.mode = to;
        event
    }

    /// One cycle at loop time `now` (s, the clock the robot's state and the tracker's samples
    /// use), phase by phase (see the module's table).
    pub fn cycle<R: Robot + ?Sized, S: PoseSource + ?Sized>(
        &mut self,
        now: f64,
        robot: &mut R,
        source: &mut S,
    ) -> CycleRecord {
        let mut rec = CycleRecord::new(now, self.mode, self.cmd.q);
        rec.head_from_coil_goal = self.cfg.head_from_coil_goal;
        rec.command_delay_s = self.cmd.delay.estimate();
        rec.standoff_m = self.standoff.distance;
        // Sense, the tracker first: samples are taken even while the robot is faulted.
        self.head.note_failures(source.failures());
        let mut event = source
            .latest()
            .and_then(|s| self.head.take_sample(s, &self.cfg.params, self.period));
        if std::mem::take(&mut self.fault.rearmed) {
            event = Some(Event::Rearmed);
        }
        // Rules: the robot's.
        let state = match self.robot_phase(now, robot, &mut rec) {
            RobotStep::Ready(state) => state,
            RobotStep::Done(to) => {
                if let Some(to) = to {
                    event = event.or(self.transition(to));
                }
                rec.mode = self.mode;
                rec.event = event;
                return rec;
            }
        };
        self.cmd
            .step_time(&state, self.period, self.cfg.params.robot_stale_s);
        // Rules: the tracker's and the force sensor's; sense: the head when the command acts.
        let tracker = self.tracker_phase(now, &mut rec, &mut event);
        let force = self.force_phase(&state, &mut rec);
        let head = self.head_estimate(now, tracker, force.is_some(), &state.actual_q, &mut rec);
        // Decide.
        let mut decision = decide(&RuleInputs {
            tracker,
            goal: self.goal.check.err().map(Reason::from),
            calibration: self.operator.calibration_invalid,
            operator: self.operator.hold,
            force,
        });
        if force.is_some() {
            self.standoff.force_landing = true;
        }
        // Target.
        rec.press_m = self.contact_press(decision.reaction);
        if let Some(bh) = head.base_from_head {
            self.update_standoff(&bh, head.required, decision.reaction, &mut rec);
        }
        let goal_q = self
            .goal_joints(decision.reaction, head.base_from_head.as_ref())
            .unwrap_or_else(|r| {
                decision = Decision::hold(r);
                None
            });
        let (desired, speed_fraction) =
            self.target(now, decision, goal_q, &head, &mut rec, &mut event);
        self.cmd.target_speed = self.target_speed(goal_q, &desired, &head);
        // Limit and filter, then check.
        let bh = head.base_from_head.as_ref();
        let (saved, q_next) =
            self.limit_and_filter(&desired, speed_fraction, bh, head.required, &mut rec);
        let q_next = self.check_phase(bh, saved, &desired, speed_fraction, q_next, &mut event);
        // Command.
        self.command(now, robot, q_next, bh, &mut rec);
        rec.mode = self.mode;
        rec.event = event;
        rec
    }

    /// Sends the command (its servo setpoint, [`Self::setpoint`]) and records it, with the
    /// commanded coil's clearance from the head.
    fn command<R: Robot + ?Sized>(
        &mut self,
        now: f64,
        robot: &mut R,
        q: [f64; 6],
        base_from_head: Option<&Isometry3<f64>>,
        rec: &mut CycleRecord,
    ) {
        if let Some(bh) = base_from_head {
            rec.clearance_m = self.commanded_clearance(&q, bh, clearance::Site::Recorded);
        }
        self.cmd.q = q;
        rec.q_command = q;
        let setpoint = self.setpoint_off_the_scalp(&q, base_from_head, rec);
        rec.q_setpoint = setpoint;
        if let Ok(seq) = robot.servo(&setpoint, &self.cfg.servo) {
            self.cmd.delay.note(seq, now);
            self.cmd.held.note_sent(seq, setpoint);
            self.cmd.servo_sent = true;
        }
        rec.command_delay_s = self.cmd.delay.estimate();
    }

    /// The servo setpoint for the command `q` (already in `self.cmd`), leading it while
    /// tracking, but without the lead where it would take the setpoint into the head at
    /// `base_from_head` (below the filter's floor, `rec.required_m` or the least distance).
    ///
    /// The arm lags the setpoint by the servo's lag, which the lead only partly makes up: it
    /// stays behind the command, which keeps the filter's clearance. The setpoint itself may
    /// not enter the head (nor press deeper than contact allows).
    fn setpoint_off_the_scalp(
        &mut self,
        q: &[f64; 6],
        base_from_head: Option<&Isometry3<f64>>,
        rec: &CycleRecord,
    ) -> [f64; 6] {
        let before = (self.cmd.lead, self.cmd.catch_up);
        let setpoint = self.setpoint(self.mode == Mode::Tracking);
        let Some(bh) = base_from_head.filter(|_| setpoint != *q) else {
            return setpoint;
        };
        let floor = rec.required_m.min(self.cfg.params.coil_min_distance_m);
        // Asked only when the lead's move could reach the floor: the coil's points move by at
        // most its centre's move plus its corner's radius times its turn.
        let (a, b) = (
            self.head_from_coil_at(q, bh),
            self.head_from_coil_at(&setpoint, bh),
        );
        let corner = self.cfg.coil.extent();
        let moved = (b.translation.vector - a.translation.vector).norm()
            + corner * a.rotation.angle_to(&b.rotation);
        let known = rec.clearance_m.min(CLEARANCE_EXACT_BELOW_M);
        if known - moved < floor
            && self.commanded_clearance(&setpoint, bh, clearance::Site::Setpoint) < floor
        {
            (self.cmd.lead, self.cmd.catch_up) = before;
            return self.setpoint(false);
        }
        setpoint
    }

    /// The servo setpoint for the command in `self.cmd`, leading it while `following` the goal
    /// ([`command::CommandState::setpoint`]).
    fn setpoint(&mut self, following: bool) -> [f64; 6] {
        let servo = (self.cfg.servo.lookahead_s, self.cfg.servo.gain);
        let p = &self.cfg.params;
        self.cmd.setpoint(
            &self.arm,
            servo,
            self.period,
            (p.catch_up_lead, p.speed_fraction),
            following,
        )
    }

    /// The coil's clearance from the head at `base_from_head` with the arm at `q`, m (exact
    /// below [`CLEARANCE_EXACT_BELOW_M`]), asked from `site`.
    fn commanded_clearance(
        &self,
        q: &[f64; 6],
        base_from_head: &Isometry3<f64>,
        site: clearance::Site,
    ) -> f64 {
        let head_from_coil = self.head_from_coil_at(q, base_from_head);
        self.clearance.at(site, |memory| {
            self.cfg.coil.distance_below_remembering(
                &self.cfg.head,
                &head_from_coil,
                CLEARANCE_EXACT_BELOW_M,
                memory,
            )
        })
    }
}

/// The event a change of mode from `from` to `to` reports: none when nothing changes, nor for a
/// new reason of the same kind (values move every cycle); a hold or a fault reports its reason,
/// a retreat its own; tracking after approaching is "reached", any other return "resume".
pub fn transition_event(from: Mode, to: Mode) -> Option<Event> {
    if from == to {
        return None;
    }
    match to {
        Mode::Holding(r) | Mode::Faulted(r) | Mode::Retreating(r) => {
            let same_kind = matches!((from, to),
                (Mode::Holding(a), Mode::Holding(b))
                | (Mode::Faulted(a), Mode::Faulted(b))
                | (Mode::Retreating(a), Mode::Retreating(b))
                    if std::mem::discriminant(&a) == std::mem::discriminant(&b));
            (!same_kind).then_some(match to {
                Mode::Retreating(_) => Event::Retreat(r),
                _ => Event::Hold(r),
            })
        }
        Mode::Tracking => Some(if from == Mode::Approaching {
            Event::Reached
        } else {
            Event::Resume
        }),
        Mode::Approaching => Some(Event::Resume),
    }
}
