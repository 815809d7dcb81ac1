//! One compensation cycle, at the robot's rate, on an injectable clock: newest tracker sample and
//! robot state → the supervisor's rules ([`crate::supervisor`]) → predicted head pose → goal
//! `base_from_flange = base_from_tracker · tracker_from_head · head_from_coil_goal ·
//! coil_from_flange`, backed off by the standoff the safety filter asks for
//! ([`crate::safety`]) → IK on the current branch → limits → the filter and the collision checks
//! on the command → `servo`. No allocation, no lock, no logging: the caller gets a
//! [`CycleRecord`] (`Copy`) to queue for a logger.

use crate::config::{LoopConfig, LoopParams};
use crate::force::{ForceMonitor, admittance_step, force_rules, is_force_reason};
use crate::goal::{GoalError, check_goal};
use crate::planner::{PlanError, ShellPath};
use crate::predict::PosePredictor;
use crate::safety::{backed_off, required_clearance, standoff_for};
pub use crate::supervisor::Reason;
use crate::supervisor::{
    Reaction, TrackerInputs, TrackerVerdict, TransitRefusal, latches, reaction, robot_rules,
    tracker_rules,
};
use crate::transit::{JointPath, profile_step};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_geom::{PoseSample, PoseSource};
use mocomp_kin::{Arm, BranchPolicy, Metric, Selection};
use mocomp_ur::Robot;

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

/// One cycle, for the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleRecord {
    /// Loop time, s.
    pub t: f64,
    /// The mode after this cycle.
    pub mode: Mode,
    /// The event of this cycle.
    pub event: Option<Event>,
    /// Age of the newest accepted tracker sample, s (NaN before the first).
    pub sample_age_s: f64,
    /// Prediction horizon from the newest sample, s (0 without prediction).
    pub horizon_s: f64,
    /// Estimated command delay (send → acknowledged in the robot's state), s.
    pub command_delay_s: f64,
    /// Joints commanded.
    pub q_command: [f64; 6],
    /// Joints measured.
    pub q_actual: [f64; 6],
    /// Joint speeds measured, rad/s.
    pub qd_actual: [f64; 6],
    /// The goal this cycle, `head_from_coil` (the selected target's).
    pub head_from_coil_goal: Isometry3<f64>,
    /// The goal flange pose computed this cycle, if any.
    pub goal: Option<Isometry3<f64>>,
    /// Estimated head speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// While approaching: arc length travelled and the path's length, m.
    pub path: Option<(f64, f64)>,
    /// The standoff along the approach axis the goal was backed off by, m.
    pub standoff_m: f64,
    /// How far the safety filter moved this cycle's command back along the approach axis, m.
    pub filtered_m: f64,
    /// The commanded coil's clearance from the head predicted for the time it acts, m (NaN
    /// without a head estimate; exact below 5 cm, at least 5 cm otherwise).
    pub clearance_m: f64,
    /// The clearance the filter required this cycle, m.
    pub required_m: f64,
    /// The loop coasts on the prediction through a tracker dropout.
    pub coasting: bool,
    /// The measured flange's distance from the goal for the head as estimated now (the state's
    /// time), m and rad: the deviation a live system can report. NaN without a head estimate.
    pub deviation: (f64, f64),
    /// The measured coil's distance from the goal's coil pose for the head as estimated now, m
    /// and rad: what the on-target gate judges (the flange's [`Self::deviation`] differs by the
    /// angle error times the coil's offset from the flange). NaN without a head estimate.
    pub coil_error: (f64, f64),
    /// The head marker now (`tracker_from_head` estimated for the cycle's time), when known:
    /// what teaching the goal while the loop runs averages.
    pub head_now: Option<Isometry3<f64>>,
    /// The filtered contact force's magnitude, N (NaN without `force_sensing`).
    pub contact_force_n: f64,
    /// The filtered force pushing the coil out along its axis, N (NaN without `force_sensing`).
    pub contact_axial_n: f64,
    /// How far contact mode presses the coil in from its goal along the axis, m.
    pub press_m: f64,
    /// Compute time of the cycle, ns (filled by the caller that owns a clock for it).
    pub compute_ns: u64,
}

impl CycleRecord {
    /// A record of a cycle at `t` in `mode` that commanded `q_command`, with nothing else known
    /// yet (NaN, none, zero).
    pub fn new(t: f64, mode: Mode, q_command: [f64; 6]) -> Self {
        Self {
            t,
            mode,
            event: None,
            sample_age_s: f64::NAN,
            horizon_s: 0.0,
            command_delay_s: f64::NAN,
            q_command,
            q_actual: [f64::NAN; 6],
            qd_actual: [f64::NAN; 6],
            head_from_coil_goal: Isometry3::identity(),
            goal: None,
            head_speed: (0.0, 0.0),
            path: None,
            standoff_m: 0.0,
            filtered_m: 0.0,
            clearance_m: f64::NAN,
            required_m: f64::NAN,
            coasting: false,
            deviation: (f64::NAN, f64::NAN),
            coil_error: (f64::NAN, f64::NAN),
            head_now: None,
            contact_force_n: f64::NAN,
            contact_axial_n: f64::NAN,
            press_m: 0.0,
            compute_ns: 0,
        }
    }
}

const ACK_RING: usize = 64;
/// Samples along a planned path checked for reachability and collisions.
const PATH_CHECKS: usize = 40;
/// Largest joint change between neighbouring path samples before it counts as a branch change,
/// rad.
const MAX_PATH_JOINT_STEP: f64 = 0.35;
/// The logged clearance is exact below this, a lower bound above (sparing the exact solve when
/// the coil is far), m.
const CLEARANCE_EXACT_BELOW_M: f64 = 0.05;
/// Deceleration of a standoff shrinking back to the goal, m/s².
const STANDOFF_LANDING_M_S2: f64 = 1.0;
/// An axial force above this means the coil touches the scalp, N (well above a sensor's noise
/// after the filter).
const TOUCH_N: f64 = 0.5;
/// Corrections of one command by the safety filter (each re-solves IK and the limits).
const FILTER_PASSES: usize = 2;
/// A joint-space transit is checked against the head at samples this far apart (the largest
/// joint's travel), rad: 2 cm at a 0.4 m lever.
const TRANSIT_CHECK_RAD: f64 = 0.05;
/// A transit's profile waits while the command lags it by more than this (largest joint), rad.
const TRANSIT_LAG_RAD: f64 = 0.02;
/// A transit has arrived when the command is this close to its end (largest joint), rad.
const TRANSIT_ARRIVED_RAD: f64 = 1e-4;

/// The compensation loop's state.
#[derive(Debug, Clone)]
pub struct Compensator {
    cfg: LoopConfig,
    arm: Arm,
    coil_from_flange: Isometry3<f64>,
    period: f64,
    predictor: PosePredictor,
    last_raw: Option<PoseSample>,
    last_valid: bool,
    identical: u32,
    q_cmd: [f64; 6],
    v_cmd: [f64; 6],
    have_cmd: bool,
    /// The previous cycle's target joints (for the target's speed).
    last_desired: Option<[f64; 6]>,
    mode: Mode,
    clear_since: Option<f64>,
    stop_sent: bool,
    /// A robot fault that stays until the operator re-arms ([`crate::supervisor::latches`]).
    latched: Option<Reason>,
    /// The operator re-armed since the last cycle: its event is the next cycle's.
    rearmed: bool,
    /// The sequence number of the stop sent for a fault, until the controller has taken it.
    stop_seq: Option<i32>,
    /// A servo command has been sent (`q_cmd` is a setpoint the controller may hold).
    servo_sent: bool,
    command_delay: f64,
    acks: [(i32, f64); ACK_RING],
    ack_head: usize,
    ack_len: usize,
    /// The planned way to the goal while approaching.
    path: Option<Plan>,
    /// Progress along it: m of shell path, or rad of the transit's largest joint.
    sigma: f64,
    sigma_dot: f64,
    replan: bool,
    last_head: Option<Isometry3<f64>>,
    /// The goal's validity ([`crate::goal::check_goal`]), fixed with the configuration.
    goal_check: Result<f64, GoalError>,
    /// The controller time of the state the previous command answered (NaN before the first).
    last_controller_s: f64,
    /// The controller time between the previous command and this one, s: the time the command
    /// is stepped by.
    dt: f64,
    /// The standoff along the approach axis the anchor is backed off by, m.
    standoff: f64,
    /// The coil pose (`head_from_coil`) the standoff backs off from: the goal, or where the coil
    /// was when it had to give way away from the goal (approaching, holding).
    anchor: Isometry3<f64>,
    /// Whether the previous cycle coasted through a dropout.
    coasting: bool,
    /// Whether this cycle's command gives way to the head (retreating): its speed limit is
    /// `retreat_tcp_speed_m_s`. (Not for the filter's small corrections: at that speed they
    /// overshoot and the servo's lag brings the coil back in.)
    giving_way: bool,
    /// Distance from the head marker to the coil at the goal, m: the lever that turns rotation
    /// uncertainty into position uncertainty at the coil.
    coil_lever: f64,
    /// The operator asks the loop to hold ([`Self::set_operator_hold`]).
    operator_hold: bool,
    /// The drift monitor's offset while the calibration is not valid.
    calibration_invalid: Option<(f64, f64)>,
    /// The operator guides the arm by hand.
    freedrive: bool,
    /// When a held coil last had to give way to the head, s (loop time).
    gave_way_at: f64,
    /// The wrench's filter and timers.
    force: ForceMonitor,
    /// The force sensor's range, N (`None`: an estimate without one).
    force_range: Option<f64>,
    /// The newest filtered axial force, N.
    axial_n: f64,
    /// Contact mode's press from the goal along the approach axis, m.
    press: f64,
    /// Coming back from a force retreat: the standoff shrinks at the admittance's pace.
    force_landing: bool,
}

impl Compensator {
    /// A loop for `arm` (its model fixes the speeds and limits) at the robot's `period_s`.
    pub fn new(cfg: LoopConfig, arm: Arm, period_s: f64) -> Self {
        let coil_from_flange = cfg.flange_from_coil.inverse();
        let cfg_goal = cfg.head_from_coil_goal;
        let predictor = PosePredictor::new(cfg.predictor);
        let force_range = mocomp_ur::ForceSource::range_n(arm.model());
        let goal_check = check_goal(
            &cfg.head,
            &cfg.coil,
            &cfg.head_from_coil_goal,
            cfg.params.goal_min_distance_m(),
        );
        Self {
            command_delay: period_s,
            coil_lever: cfg.head_from_coil_goal.translation.vector.norm(),
            cfg,
            arm,
            coil_from_flange,
            period: period_s,
            predictor,
            last_raw: None,
            last_valid: true,
            identical: 0,
            q_cmd: [0.0; 6],
            v_cmd: [0.0; 6],
            have_cmd: false,
            last_desired: None,
            mode: Mode::Holding(Reason::NoTracker),
            clear_since: None,
            stop_sent: false,
            latched: None,
            rearmed: false,
            stop_seq: None,
            servo_sent: false,
            acks: [(0, 0.0); ACK_RING],
            ack_head: 0,
            ack_len: 0,
            path: None,
            sigma: 0.0,
            sigma_dot: 0.0,
            replan: false,
            last_head: None,
            last_controller_s: f64::NAN,
            dt: period_s,
            goal_check,
            standoff: 0.0,
            anchor: cfg_goal,
            coasting: false,
            giving_way: false,
            operator_hold: false,
            calibration_invalid: None,
            freedrive: false,
            gave_way_at: f64::NEG_INFINITY,
            force: ForceMonitor::new(),
            force_range,
            axial_n: 0.0,
            press: 0.0,
            force_landing: false,
        }
    }

    /// The operator's hold (`true`) or resume (`false`). A hold stops following the head where
    /// the coil is, with [`Reason::Operator`] (the supervisor's other rules outrank it); the coil
    /// still gives way to a head that comes closer than the safety filter requires. A resume
    /// comes back as after any hold: `resume_after_s`, then by a planned path when the coil is
    /// off its goal. Takes effect at the next cycle.
    pub fn set_operator_hold(&mut self, hold: bool) {
        self.operator_hold = hold;
    }

    /// The operator's re-arm after a latched fault (the console's or a front end's resume, once
    /// the robot's own recovery — reconnect, program restart, a protective stop unlocked — is
    /// done). Clears the latch; the robot rules still apply, so a fault that persists latches
    /// again at the next cycle. Comes back as after any fault: `resume_after_s` of a healthy
    /// robot, then from the arm's actual pose by a planned path. Returns whether a fault was
    /// latched.
    pub fn rearm(&mut self) -> bool {
        let was = self.latched.take().is_some();
        if was {
            self.clear_since = None;
            self.rearmed = true;
        }
        was
    }

    /// The latched fault that waits for the operator's re-arm, if any.
    pub fn latched(&self) -> Option<Reason> {
        self.latched
    }

    /// The calibration no longer holds (the drift monitor's offset, m and rad): the loop holds
    /// with [`Reason::CalibrationInvalid`] until `None` (a new calibration). Faults, force rules
    /// and the coil's giving way outrank it; the operator's hold and the goal's check do not.
    pub fn set_calibration_invalid(&mut self, offset: Option<(f64, f64)>) {
        self.calibration_invalid = offset;
    }

    /// Free-drive (`true`): from the next cycle the loop sends free-drive's keep-alive instead
    /// of a command, the arm yielding to the operator's hand, and holds with
    /// [`Reason::HandGuided`] (the head is still tracked, so the coil's pose on it can be taught).
    /// Its end (`false`) hands back to the loop from the arm's actual pose: the command starts
    /// there, and the goal is reached by a planned path, never straight from where the hand left
    /// the coil. A fault ends free-drive on the robot; the loop stays hand-guided until told.
    pub fn set_freedrive(&mut self, on: bool) {
        if self.freedrive && !on {
            self.have_cmd = false;
            self.path = None;
            self.replan = true;
            self.anchor = self.cfg.head_from_coil_goal;
            self.standoff = 0.0;
            self.clear_since = None;
        }
        self.freedrive = on;
    }

    /// Whether the arm is hand-guided.
    pub fn freedrive(&self) -> bool {
        self.freedrive
    }

    /// Whether the operator holds the loop.
    pub fn operator_hold(&self) -> bool {
        self.operator_hold
    }

    /// A new goal (`head_from_coil`), from the next cycle: taught while the loop runs. Refused,
    /// with the goal unchanged, when the goal check refuses it. The coil goes to it by a planned
    /// path once the loop follows again.
    pub fn set_goal(&mut self, head_from_coil: &Isometry3<f64>) -> Result<(), GoalError> {
        let clear = check_goal(
            &self.cfg.head,
            &self.cfg.coil,
            head_from_coil,
            self.cfg.params.goal_min_distance_m(),
        )?;
        if self.anchor == self.cfg.head_from_coil_goal {
            self.anchor = *head_from_coil;
            self.standoff = 0.0;
        }
        self.cfg.head_from_coil_goal = *head_from_coil;
        self.goal_check = Ok(clear);
        self.coil_lever = head_from_coil.translation.vector.norm();
        self.path = None;
        self.replan = true;
        Ok(())
    }

    /// New loop parameters, from the next cycle (the console's tuning). The goal's check, which
    /// depends on `coil_min_distance_m`, is redone; a goal the new parameters refuse holds the
    /// loop with its reason, as at start. The caller has validated them.
    pub fn set_params(&mut self, params: LoopParams) {
        self.cfg.params = params;
        self.goal_check = check_goal(
            &self.cfg.head,
            &self.cfg.coil,
            &self.cfg.head_from_coil_goal,
            params.goal_min_distance_m(),
        );
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

    /// The measured flange's and the measured coil's errors (m, rad) against the goal for the
    /// head at `tracker_from_head`, with the arm at `q`.
    fn measured_errors(
        &self,
        q: &[f64; 6],
        tracker_from_head: &Isometry3<f64>,
    ) -> ((f64, f64), (f64, f64)) {
        let goal_now = self.goal_for(tracker_from_head);
        let flange = self.arm.fk_flange(q);
        let angle = flange.rotation.angle_to(&goal_now.rotation);
        let (coil, coil_goal) = (
            flange * self.cfg.flange_from_coil,
            goal_now * self.cfg.flange_from_coil,
        );
        (
            (
                (flange.translation.vector - goal_now.translation.vector).norm(),
                angle,
            ),
            (
                (coil.translation.vector - coil_goal.translation.vector).norm(),
                angle,
            ),
        )
    }

    /// Takes the newest tracker sample, applying the tracker rules. Returns an outlier event.
    fn take_sample(&mut self, s: PoseSample) -> Option<Event> {
        if self.predictor.is_initialised() && s.acquired_s <= self.predictor.time_s() {
            // Acquired before the newest sample taken (a sender's clock stepped back, not yet
            // re-based): it says nothing about the head now, and judged as a motion it would
            // look like a jump. The newest sample keeps ageing, so the tracker rules hold.
            return None;
        }
        self.last_valid = s.valid;
        if !s.valid {
            return None;
        }
        if let Some(prev) = self.last_raw {
            if prev.tracker_from_marker == s.tracker_from_marker {
                self.identical = self.identical.saturating_add(1);
            } else {
                self.identical = 0;
            }
        }
        let p = &self.cfg.params;
        if self.predictor.is_initialised()
            && s.acquired_s - self.predictor.time_s() > p.tracker_stale_s + p.coast_s
        {
            // Back after the tracker was lost: the old rates mean nothing for the head now.
            self.predictor.reset();
            self.last_raw = None;
            self.identical = 0;
        }
        if let Some(pred) = self.predictor.predict(s.acquired_s) {
            let dt = (s.acquired_s - self.predictor.time_s()).max(self.period);
            let lin = (pred.translation.vector - s.tracker_from_marker.translation.vector).norm();
            let ang = (pred.rotation.inverse() * s.tracker_from_marker.rotation).angle();
            let (vl, va) = (lin / dt, ang / dt);
            if vl > self.cfg.params.outlier_speed_m_s || va > self.cfg.params.outlier_speed_rad_s {
                return Some(Event::Outlier(vl, va));
            }
        }
        self.last_raw = Some(s);
        self.predictor.update(s.acquired_s, &s.tracker_from_marker);
        None
    }

    /// The tracker rules' verdict now (see [`crate::supervisor::tracker_rules`]).
    fn tracker_verdict(&mut self, now: f64) -> TrackerVerdict {
        let p = &self.cfg.params;
        let age = now - self.predictor.time_s();
        if self.predictor.is_initialised() && age > 10.0 * (p.tracker_stale_s + p.coast_s) {
            // A long dropout: the velocity estimate means nothing any more.
            self.predictor.reset();
            self.last_raw = None;
        }
        let (v, w) = self.predictor.velocity();
        tracker_rules(
            &TrackerInputs {
                initialised: self.predictor.is_initialised(),
                valid: self.last_valid,
                age_s: age,
                identical: self.identical,
                speed: (v.norm(), w.norm()),
            },
            p,
        )
    }

    /// The flange target for the head at `base_from_head`: the anchor (usually the goal),
    /// backed off by the current standoff.
    fn standoff_target(&self, base_from_head: &Isometry3<f64>) -> Isometry3<f64> {
        base_from_head
            * backed_off(&self.anchor, self.standoff - self.press)
            * self.coil_from_flange
    }

    /// Whether contact mode holds the coil on the scalp now (following the goal).
    fn in_contact_mode(&self) -> bool {
        let p = &self.cfg.params;
        p.contact_mode && p.force_sensing && self.mode == Mode::Tracking
    }

    /// The coil at joints `q` seen from the head at `base_from_head`.
    fn head_from_coil_at(&self, q: &[f64; 6], base_from_head: &Isometry3<f64>) -> Isometry3<f64> {
        base_from_head.inverse() * self.arm.fk_flange(q) * self.cfg.flange_from_coil
    }

    /// Re-solves this cycle's command for the current standoff plus `extra` (m), from the state
    /// before the limits ran (`saved`), so a correction is limited like any command. The
    /// target's speed stays the uncorrected target's (`nominal`): a correction is not a motion to
    /// keep. `None` when the IK fails.
    fn retarget(
        &mut self,
        base_from_head: &Isometry3<f64>,
        extra: f64,
        saved: ([f64; 6], [f64; 6], Option<[f64; 6]>),
        nominal: &[f64; 6],
        speed_fraction: f64,
    ) -> Option<[f64; 6]> {
        let s = (self.standoff - self.press + extra).min(self.cfg.params.max_standoff_m);
        let target = base_from_head * backed_off(&self.anchor, s) * self.coil_from_flange;
        let c = self
            .arm
            .ik_closest(
                &target,
                &saved.0,
                &Selection::tracking(self.cfg.params.joint_margin_rad),
            )
            .ok()?;
        (self.q_cmd, self.v_cmd, self.last_desired) = saved;
        let q = self.limit(&c.joints, speed_fraction);
        self.last_desired = Some(*nominal);
        Some(q)
    }

    fn note_command(&mut self, seq: i32, t: f64) {
        let i = (self.ack_head + self.ack_len) % ACK_RING;
        self.acks[i] = (seq, t);
        if self.ack_len < ACK_RING {
            self.ack_len += 1;
        } else {
            self.ack_head = (self.ack_head + 1) % ACK_RING;
        }
    }

    fn measure_delay(&mut self, acked: i32, received_s: f64) {
        while self.ack_len > 0 {
            let (seq, sent) = self.acks[self.ack_head];
            if acked.wrapping_sub(seq) < 0 {
                break;
            }
            if acked == seq {
                let d = (received_s - sent).max(0.0);
                self.command_delay += 0.05 * (d - self.command_delay);
            }
            self.ack_head = (self.ack_head + 1) % ACK_RING;
            self.ack_len -= 1;
        }
    }

    /// Rate- and acceleration-limits the command towards `desired`, joint by joint, so that each
    /// joint can still stop at `desired` within its acceleration, relative to the target's own
    /// motion: a moving target is followed at its speed (feed-forward), not approached as if it
    /// stood still, which would lag it by the braking distance. The target's speed is over the
    /// controller time since the previous command (`self.dt`); the step itself is never longer
    /// than one controller period's: the controller judges a setpoint against its previous one,
    /// which it may have taken only one period ago however long this state took to come (a
    /// controller that stalled and caught up, a network that held the previous command back),
    /// so after any gap the command goes on from the last setpoint within the per-cycle limit
    /// (URControl's C204A3) and makes up the lost time over the following cycles. A cycle with
    /// no controller time passed moves nothing.
    fn limit(&mut self, desired: &[f64; 6], speed_fraction: f64) -> [f64; 6] {
        if self.dt <= 0.0 {
            return self.q_cmd;
        }
        let target_dt = self.dt;
        let dt = self.dt.min(self.period);
        let a = self.cfg.params.max_joint_accel_rad_s2;
        let mut q = self.q_cmd;
        let mut v = self.v_cmd;
        let previous = self.last_desired.replace(*desired);
        for j in 0..6 {
            let vmax = self.arm.spec().max_speed[j] * speed_fraction;
            // The target's speed, from its last two values; a jump (a new mode, a retreat) is
            // not a speed to keep.
            let v_target = previous
                .map(|p| (desired[j] - p[j]) / target_dt)
                .filter(|v| v.abs() <= vmax)
                .unwrap_or(0.0);
            let delta = desired[j] - self.q_cmd[j];
            // Largest speed relative to the target from which the joint can still stop on it in
            // whole cycles of deceleration a·dt each: n·a·dt with a·dt²·n(n+1)/2 ≤ |delta| (the
            // continuous √(2a|delta|) overshoots by up to a cycle and chatters around a still
            // target).
            let adt2 = a * dt * dt;
            let n = 0.5 * ((1.0 + 8.0 * delta.abs() / adt2).sqrt() - 1.0);
            let v_stop = n * a * dt;
            let want =
                (v_target + (delta / dt - v_target).clamp(-v_stop, v_stop)).clamp(-vmax, vmax);
            v[j] = want.clamp(self.v_cmd[j] - a * dt, self.v_cmd[j] + a * dt);
            q[j] = self.q_cmd[j] + v[j] * dt;
        }
        // The coil's speed limit, on the whole step.
        let p0 = self.arm.fk(&self.q_cmd).translation.vector;
        let p1 = self.arm.fk(&q).translation.vector;
        let speed = (p1 - p0).norm() / dt;
        let p = &self.cfg.params;
        let tcp_limit = if self.giving_way {
            p.max_tcp_speed_m_s.max(p.retreat_tcp_speed_m_s)
        } else {
            p.max_tcp_speed_m_s
        };
        if speed > tcp_limit {
            let k = tcp_limit / speed;
            for j in 0..6 {
                v[j] *= k;
                q[j] = self.q_cmd[j] + v[j] * dt;
            }
        }
        self.v_cmd = v;
        q
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
        let frames = self.arm.link_frames(q);
        // The previous command's links are needed only near the head (rare), its flange always.
        let mut prev_frames: Option<[Isometry3<f64>; 7]> = None;
        let prev_flange = self.arm.fk_flange(q_prev);
        let head = &self.cfg.head;
        let point_at = |f: &[Isometry3<f64>; 7], i: usize, k: u32| {
            let a = f[i - 1].translation.vector;
            let b = f[i].translation.vector;
            Point3::from(a + (b - a) * (f64::from(k) / 4.0))
        };
        // Links up to wrist 2; wrist 3 and the flange are inside the coil's model.
        let (radius, clearance) = (
            self.cfg.params.link_radius_m,
            self.cfg.params.link_clearance_m,
        );
        for i in 1..6 {
            for k in 0..=4 {
                let p = point_at(&frames, i, k);
                let d = head.distance_below(&(now_from_base * p), clearance + radius) - radius;
                if d < clearance {
                    let pf = prev_frames.get_or_insert_with(|| self.arm.link_frames(q_prev));
                    let p0 = point_at(pf, i, k);
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
        // Both flanges by the same computation: a command that does not move must compare equal
        // to itself to the last bit, or a hold would refuse to stay where it is.
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
        let nearest = self
            .cfg
            .coil
            .distance_below(&self.cfg.head, &coil_now, deepest);
        if nearest < deepest
            && nearest
                < self
                    .coil_distance(&coil_prev_now)
                    .min(self.coil_distance(&coil_prev_prev))
        {
            return Some(Reason::CoilCollision(nearest));
        }
        let centre = coil_now.translation.vector;
        let zone = self.cfg.params.approach_zone_m;
        let d = head.distance_below(&Point3::from(centre), zone);
        let (p1, p2) = (
            coil_prev_now.translation.vector,
            coil_prev_prev.translation.vector,
        );
        let d_prev = || {
            head.distance(&Point3::from(p1))
                .min(head.distance(&Point3::from(p2)))
        };
        if approach_rule && d < zone && d < d_prev() - 1e-6 {
            // Near the head the coil moves only along an approach axis: the goal's, or on a
            // path the axis it set out along (leaving one target for its neighbour, the coil
            // backs out along its own axis, which is off the new goal's).
            let axis_of = |g: &Isometry3<f64>| (g.translation.vector, g.rotation * Vector3::z());
            let axes = [
                Some(axis_of(&self.cfg.head_from_coil_goal)),
                self.path
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
            if lateral > self.cfg.params.approach_tolerance_m
                && lateral >= lateral_of(p1).max(lateral_of(p2))
            {
                return Some(Reason::OffApproachAxis(lateral));
            }
        }
        None
    }

    /// The coil's nearest distance to the head (its face rim, centre and back), m.
    fn coil_distance(&self, head_from_coil: &Isometry3<f64>) -> f64 {
        self.cfg.coil.distance(&self.cfg.head, head_from_coil)
    }

    /// Plans the way from the commanded pose to the goal around the head at `base_from_head`: a
    /// shell path when the coil is near the head and the path has a solution on the current
    /// branch, else a joint-space transit to the goal's approach axis away from the head on a
    /// branch the approach has a solution on (see [`crate::transit`]).
    fn plan(&self, base_from_head: &Isometry3<f64>) -> Result<Plan, Reason> {
        let p = &self.cfg.params;
        let clearance = self.coil_distance(&self.head_from_coil_at(&self.q_cmd, base_from_head));
        let near = clearance <= p.transit_distance_m + p.shell_distance_m;
        let shell = if near {
            match self.plan_shell(&self.q_cmd, base_from_head) {
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
            let flange = base_from_head * path.pose_at(sigma) * self.coil_from_flange;
            let next = self
                .arm
                .ik_closest(
                    &flange,
                    &q,
                    &Selection::tracking(self.cfg.params.joint_margin_rad),
                )
                .map_err(|_| Reason::NoPath(sigma))?
                .joints;
            let jump = (0..6).fold(0.0f64, |m, j| m.max((next[j] - q[j]).abs()));
            if jump > MAX_PATH_JOINT_STEP
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
            .ik(&flange, self.q_cmd[5])
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
            if let Ok(c) = self.arm.choose(&sols, &self.q_cmd, &sel) {
                cands[n] = (c.cost, c.joints);
                n += 1;
            }
        }
        cands[..n].sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        let mut furthest = TransitRefusal::Unreachable;
        for (_, q) in &cands[..n] {
            let path = JointPath::new(self.q_cmd, *q);
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
                let (a, b) = (
                    frames[i - 1].translation.vector,
                    frames[i].translation.vector,
                );
                for s in 0..=4 {
                    let point = Point3::from(a + (b - a) * (f64::from(s) / 4.0));
                    let d = self.cfg.head.distance(&(head_from_base * point)) - p.link_radius_m;
                    if d < p.link_clearance_m {
                        return false;
                    }
                }
            }
        }
        true
    }

    /// Advances along the path (a speed-limited, acceleration-limited arc-length profile that
    /// waits for the command when it lags) and returns the flange target at the new arc length.
    fn path_target(&mut self, path: &ShellPath, base_from_head: &Isometry3<f64>) -> Isometry3<f64> {
        let dt = self.dt;
        let a = self.cfg.params.approach_accel_m_s2;
        let here = base_from_head * path.pose_at(self.sigma) * self.coil_from_flange;
        let lag =
            (self.arm.fk_flange(&self.q_cmd).translation.vector - here.translation.vector).norm();
        let remaining = (path.length() - self.sigma).max(0.0);
        let want = if lag < self.cfg.params.path_lag_m {
            self.cfg
                .params
                .approach_speed_m_s
                .min((2.0 * a * remaining).sqrt())
        } else {
            0.0
        };
        self.sigma_dot = want.clamp(self.sigma_dot - a * dt, self.sigma_dot + a * dt);
        let p = &self.cfg.params;
        if p.force_sensing && self.axial_n > p.contact_force_n {
            // Touching before the path's end: stop where it touches, at once.
            self.sigma_dot = 0.0;
        }
        self.sigma = (self.sigma + self.sigma_dot * dt).min(path.length());
        base_from_head * path.pose_at(self.sigma) * self.coil_from_flange
    }

    /// A hold's target: the last command, standing. Its speed is zero, so the limits
    /// decelerate the arm to standstill on it; a target taken as moving at the command's own
    /// speed (the feed-forward of a followed target) would keep the arm going forever.
    fn stand_still(&mut self) -> [f64; 6] {
        self.last_desired = None;
        self.q_cmd
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
        let here = self.head_from_coil_at(&self.q_cmd, base_from_head);
        let clearance = self.coil_distance(&here);
        let giving_way =
            matches!(self.mode, Mode::Retreating(_)) && now - self.gave_way_at < p.retreat_resume_s;
        if clearance < required {
            if !giving_way {
                self.anchor = here;
                self.standoff = 0.0;
            }
            self.gave_way_at = now;
        } else if !giving_way {
            return None;
        }
        self.standoff = self.standoff.max(p.retreat_distance_m);
        let why = match self.mode {
            Mode::Retreating(r) if giving_way => r,
            _ => Reason::CoilCollision(clearance),
        };
        self.arm
            .ik_closest(
                &self.standoff_target(base_from_head),
                &self.q_cmd,
                &Selection::tracking(p.joint_margin_rad),
            )
            .ok()
            .map(|c| (c.joints, why))
    }

    fn enter(&mut self, mode: Mode) -> Option<Event> {
        if self.mode == mode {
            return None;
        }
        let event = match mode {
            Mode::Holding(r) | Mode::Faulted(r) | Mode::Retreating(r) => {
                // Report a new reason only when the kind changes (values move every cycle).
                let same_kind = matches!((self.mode, mode),
                    (Mode::Holding(a), Mode::Holding(b))
                    | (Mode::Faulted(a), Mode::Faulted(b))
                    | (Mode::Retreating(a), Mode::Retreating(b))
                        if std::mem::discriminant(&a) == std::mem::discriminant(&b));
                (!same_kind).then_some(match mode {
                    Mode::Retreating(_) => Event::Retreat(r),
                    _ => Event::Hold(r),
                })
            }
            Mode::Tracking => Some(if self.mode == Mode::Approaching {
                Event::Reached
            } else {
                Event::Resume
            }),
            Mode::Approaching => Some(Event::Resume),
        };
        self.mode = mode;
        event
    }

    /// One cycle at loop time `now` (s, the clock the robot's state and the tracker's samples
    /// use).
    pub fn cycle<R: Robot + ?Sized, S: PoseSource + ?Sized>(
        &mut self,
        now: f64,
        robot: &mut R,
        source: &mut S,
    ) -> CycleRecord {
        let mut rec = CycleRecord::new(now, self.mode, self.q_cmd);
        rec.head_from_coil_goal = self.cfg.head_from_coil_goal;
        rec.command_delay_s = self.command_delay;
        rec.standoff_m = self.standoff;
        // Tracker first: samples are taken even while the robot is faulted.
        let mut event = source.latest().and_then(|s| self.take_sample(s));
        if std::mem::take(&mut self.rearmed) {
            event = Some(Event::Rearmed);
        }

        // The robot rules.
        let state = robot.state();
        if let Some(s) = state {
            rec.q_actual = s.actual_q;
            rec.qd_actual = s.actual_qd;
            self.measure_delay(s.acked_seq, s.received_s);
        }
        let fired = robot_rules(state.as_ref(), now, &self.cfg.params);
        if let Some(r) = fired
            && self.latched.is_none()
        {
            let stale_for = state.map_or(f64::INFINITY, |s| now - s.received_s);
            if latches(&r, stale_for, &self.cfg.params) {
                self.latched = Some(r);
            }
        }
        // A rule that fires now names the fault; a cleared one that latched keeps it.
        if let Some(r) = fired.or(self.latched) {
            // Reaction::Fault, the only reaction of the robot rules.
            if self.stop_sent {
                // The stop again (an edge command: it runs once), so the controller's watchdog
                // sees the client alive and the stop is there to take when it reads again.
                let _ = robot.keep_alive();
            } else {
                // Best effort: the robot may be unreachable.
                self.stop_seq = robot.stop(self.cfg.params.stop_decel_rad_s2).ok();
                self.stop_sent = true;
            }
            self.have_cmd = false;
            self.clear_since = None;
            event = event.or(self.enter(Mode::Faulted(r)));
            rec.mode = self.mode;
            rec.event = event;
            return rec;
        }
        let Some(state) = state else { return rec };
        if let Some(seq) = self.stop_seq
            && !self.have_cmd
        {
            if state.acked_seq.wrapping_sub(seq) < 0
                || state.program_mode == mocomp_ur::program::mode::STOPPING
            {
                // Healthy again, but the controller has not yet taken the stop, or is still in it:
                // commands go into registers, so a command sent before it read the stop would
                // overwrite it and be judged against the old setpoint it still servoes to (a
                // jump); and a blocking stopj ignores commands until the arm is still, then judges
                // the next against where the arm stopped. Wait for the stop to finish, keeping
                // the link alive.
                let _ = robot.keep_alive();
                rec.mode = self.mode;
                rec.event = event;
                return rec;
            }
            self.stop_seq = None;
        }
        self.stop_sent = false;
        if self.freedrive {
            // The hand moves the arm: the loop keeps free-drive alive, follows where the arm is
            // and keeps estimating the head (to teach the coil's pose on it).
            self.have_cmd = false;
            self.last_controller_s = state.controller_s;
            self.q_cmd = state.actual_q;
            rec.q_command = state.actual_q;
            if let Ok(seq) = robot.freedrive() {
                self.note_command(seq, now);
            }
            let (v, w) = self.predictor.velocity();
            rec.head_speed = (v.norm(), w.norm());
            if self.predictor.is_initialised() {
                rec.sample_age_s = now - self.predictor.time_s();
            }
            if let Some(tracker_from_head) = self.predictor.predict(now) {
                rec.head_now = Some(tracker_from_head);
                (rec.deviation, rec.coil_error) =
                    self.measured_errors(&state.actual_q, &tracker_from_head);
            }
            event = event.or(self.enter(Mode::Holding(Reason::HandGuided)));
            rec.mode = self.mode;
            rec.event = event;
            return rec;
        }
        // Step by the controller's time, not the loop's: what matters is how long the controller
        // held the previous setpoint. Several states that arrive together give one longer step;
        // a cycle on the same state (woken without a new one) gives none.
        self.dt = if self.last_controller_s.is_finite() {
            let raw = state.controller_s - self.last_controller_s;
            // The controller's clock advances in whole periods: the difference of two large
            // times carries rounding that depends on how long the controller has been up, which
            // would make the same run differ in its last bits from one start to the next.
            let periods = (raw / self.period).round();
            let dt = if (raw - periods * self.period).abs() < 1e-6 {
                periods * self.period
            } else {
                raw
            };
            dt.clamp(0.0, self.cfg.params.robot_stale_s)
        } else {
            self.period
        };
        self.last_controller_s = state.controller_s;
        if !self.have_cmd {
            if state.program_mode == mocomp_ur::program::mode::SERVO && self.servo_sent {
                // The controller still servoes to the last setpoint (a stop that never reached
                // it): it judges the next one against that, so the command goes on from there,
                // standing.
                self.v_cmd = [0.0; 6];
            } else {
                // Start (or come back after a stop) from where the arm is and how it moves, so
                // the first command continues its motion instead of jerking it to a halt.
                self.q_cmd = state.actual_q;
                self.v_cmd = std::array::from_fn(|j| {
                    let v = state.actual_qd[j];
                    if v.is_finite() { v } else { 0.0 }
                });
            }
            self.dt = self.period;
            self.have_cmd = true;
            self.last_desired = None;
        }

        // The tracker rules.
        let verdict = self.tracker_verdict(now);
        let (v, w) = self.predictor.velocity();
        rec.head_speed = (v.norm(), w.norm());
        // No sample yet: no age (not the time since the predictor's t = 0).
        rec.sample_age_s = if self.predictor.is_initialised() {
            now - self.predictor.time_s()
        } else {
            f64::NAN
        };
        let coasting = matches!(verdict, TrackerVerdict::Coasting(_));
        if let TrackerVerdict::Coasting(age) = verdict
            && !self.coasting
        {
            event = event.or(Some(Event::Coasting(age)));
        }
        self.coasting = coasting;
        rec.coasting = coasting;
        let mut reason = match verdict {
            TrackerVerdict::Refused(r) => Some(r),
            TrackerVerdict::Fresh | TrackerVerdict::Coasting(_) => None,
        };

        // The force rules, on the wrench of this state.
        let mut force_reason = None;
        if self.cfg.params.force_sensing {
            let axis = (self.arm.fk_flange(&state.actual_q) * self.cfg.flange_from_coil).rotation
                * Vector3::z();
            let f = self.force.update(
                state.controller_s,
                &state.tcp_force,
                &axis,
                &self.cfg.params,
            );
            rec.contact_force_n = f.force_n;
            rec.contact_axial_n = f.axial_n;
            self.axial_n = f.axial_n;
            force_reason = force_rules(&f, &self.cfg.params, self.force_range);
        }

        // The head where it will be when this cycle's command acts, and the clearance the coil
        // must keep from it then. Known while tracking, coasting, and retreating from a head too
        // fast to follow.
        let head_known =
            reason.is_none() || reason.is_some_and(|r| reaction(&r) == Reaction::Retreat);
        let mut base_from_head = None;
        let mut required = self.cfg.params.coil_min_distance_m;
        if head_known {
            let (head, sigma) = if self.cfg.params.predict {
                // The servo follows its setpoint with a lag of the lookahead less one controller
                // period (the cycle that takes a setpoint already moves towards it; measured on
                // the simulated controller: 22 ms for 30 ms on a CB3, 28 ms on an e-Series).
                let servo_lag = (self.cfg.servo.lookahead_s - self.period).max(0.0);
                let target_t = now + self.command_delay + servo_lag;
                rec.horizon_s = target_t - self.predictor.time_s();
                (
                    self.predictor.predict(target_t),
                    self.predictor.sigma(target_t),
                )
            } else {
                (
                    self.last_raw.map(|s| s.tracker_from_marker),
                    self.predictor.sigma(self.predictor.time_s()),
                )
            };
            if let Some(tracker_from_head) = head {
                base_from_head = Some(self.cfg.base_from_tracker * tracker_from_head);
                required = required_clearance(&self.cfg.params, sigma.0, sigma.1, self.coil_lever);
            }
        }
        if base_from_head.is_none() && force_reason.is_some() {
            // Backing off needs a head to back off from: the last one known, where the coil
            // was pressing.
            base_from_head = self.last_head;
        }
        if self.in_contact_mode() {
            // On the scalp by design: the force rules guard the contact, the filter only how
            // deep the coil may go.
            required = -self.cfg.params.contact_max_press_m;
        }
        rec.required_m = required;
        if head_known && let Some(tracker_from_head) = self.predictor.predict(now) {
            rec.head_now = Some(tracker_from_head);
            (rec.deviation, rec.coil_error) =
                self.measured_errors(&state.actual_q, &tracker_from_head);
        }
        if let Err(e) = self.goal_check {
            // A wrong goal outranks everything but a fault.
            reason = Some(Reason::from(e));
        }
        if let Some((m, a)) = self.calibration_invalid
            && reason.is_none_or(|r| reaction(&r) == Reaction::Hold)
        {
            reason = Some(Reason::CalibrationInvalid(m, a));
        }
        if self.operator_hold && reason.is_none() {
            reason = Some(Reason::Operator);
        }
        if force_reason.is_some() {
            // A coil that may press on the scalp outranks everything but a fault.
            reason = force_reason;
            self.force_landing = true;
        }
        let mut react = reason.map_or(Reaction::Track, |r| reaction(&r));

        // Contact mode's press along the axis: the admittance while following the goal.
        if self.in_contact_mode() && react == Reaction::Track {
            let max_press = self.goal_check.unwrap_or(0.0) + self.cfg.params.contact_max_press_m;
            self.press = admittance_step(
                self.press,
                self.axial_n,
                self.dt,
                &self.cfg.params,
                max_press,
            );
        } else {
            self.press = 0.0;
        }
        rec.press_m = self.press;

        // The standoff the goal needs: the filter's, and the retreat's while retreating. It
        // grows at once and shrinks at `standoff_return_m_s`.
        if let Some(bh) = base_from_head {
            let p = &self.cfg.params;
            // The goal's own clearance is fixed (the goal check's); only a larger requirement
            // asks for a standoff.
            let goal_clear = self.goal_check.unwrap_or(f64::NEG_INFINITY);
            let mut need = if required <= goal_clear {
                0.0
            } else {
                standoff_for(
                    &self.cfg.head,
                    &self.cfg.coil,
                    &self.cfg.head_from_coil_goal,
                    required,
                    p.max_standoff_m,
                )
            };
            if react == Reaction::Retreat || matches!(self.mode, Mode::Retreating(_)) {
                need = need.max(p.retreat_distance_m);
            }
            // Coming back in, the coil lands softly: its speed falls with the standoff left, so
            // it stops on the goal instead of overshooting into the scalp.
            let mut back = p
                .standoff_return_m_s
                .min((2.0 * STANDOFF_LANDING_M_S2 * self.standoff).sqrt());
            let mut relief = 0.0;
            if p.force_sensing {
                // A coil that meets the scalp before its goal (the head model or the calibration
                // is off by more than the goal's standoff) stops coming in where it touches
                // lightly, and one pressing harder backs off to that light touch at the
                // admittance's pace (contact mode presses by its own admittance instead); back
                // from a force retreat it comes in at that pace too.
                if self.axial_n > p.contact_force_n {
                    back = 0.0;
                    if !self.in_contact_mode() {
                        relief = ((self.axial_n - p.contact_force_n) / p.contact_damping_n_s_m)
                            .min(p.retreat_tcp_speed_m_s);
                        self.force_landing = true;
                    }
                } else if self.force_landing {
                    // Clear of the scalp at the admittance's top speed, touching by its law.
                    let touching = self.axial_n > TOUCH_N;
                    back = back.min(if touching {
                        (p.contact_force_n - self.axial_n) / p.contact_damping_n_s_m
                    } else {
                        p.contact_speed_m_s
                    });
                }
            }
            self.standoff = need.max(self.standoff - back * self.dt + relief * self.dt);
            if self.standoff <= need {
                self.force_landing = false;
            }
            rec.standoff_m = self.standoff;
            rec.goal = Some(bh * self.cfg.head_from_coil_goal * self.coil_from_flange);
        }

        // The goal's joints.
        let mut goal_q = None;
        if let (Reaction::Track | Reaction::Retreat, Some(bh)) = (react, base_from_head) {
            let target = self.standoff_target(&bh);
            let margin = self.cfg.params.joint_margin_rad;
            let solved = self
                .arm
                .ik_closest(&target, &self.q_cmd, &Selection::tracking(margin))
                .or_else(|e| {
                    // Not yet following (holding, faulted, on the way): a goal on another
                    // branch is reached by a transit, which the planner decides; following, the
                    // loop never changes branch.
                    if matches!(self.mode, Mode::Tracking | Mode::Retreating(_)) {
                        Err(e)
                    } else {
                        let any = Selection {
                            branch: BranchPolicy::Any,
                            ..Selection::tracking(margin)
                        };
                        self.arm.ik_closest(&target, &self.q_cmd, &any)
                    }
                });
            match solved {
                Err(_) => reason = Some(Reason::Unreachable),
                Ok(c) => {
                    let m = self.arm.singularity_margin(&c.joints);
                    if m < self.cfg.params.singularity_hold {
                        reason = Some(Reason::Singular(m));
                    } else {
                        goal_q = Some((c.joints, m));
                    }
                }
            }
            if goal_q.is_none() {
                react = Reaction::Hold;
            }
        }

        // The mode and this cycle's target.
        let mut speed_fraction = self.cfg.params.speed_fraction;
        let desired = match (react, reason, goal_q, base_from_head) {
            (Reaction::Retreat, Some(r), Some((q, _)), Some(_)) => {
                // Keep following the head from the standoff.
                self.clear_since = None;
                self.path = None;
                event = event.or(self.enter(Mode::Retreating(r)));
                q
            }
            (Reaction::Track, _, Some((q, margin)), Some(bh)) => {
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
                    if matches!(self.mode, Mode::Retreating(_)) {
                        q
                    } else {
                        self.stand_still()
                    }
                } else {
                    // A new goal while approaching drops the path: plan again, never go straight.
                    if self.mode != Mode::Approaching || self.path.is_none() {
                        let from_retreat = matches!(self.mode, Mode::Retreating(_));
                        if self.anchor != self.cfg.head_from_coil_goal {
                            // The coil gave way away from the goal (approaching, holding): back
                            // to the goal by a path, never straight in from the side.
                            self.anchor = self.cfg.head_from_coil_goal;
                            self.standoff = 0.0;
                            self.replan = true;
                        }
                        let cmd = self.arm.fk_flange(&self.q_cmd);
                        let target = self.standoff_target(&bh);
                        let far = (cmd.translation.vector - target.translation.vector).norm()
                            > self.cfg.params.servo_deviation_m
                            || cmd.rotation.angle_to(&target.rotation)
                                > self.cfg.params.plan_rotation_rad;
                        // Back from a retreat on the goal's axis the coil comes straight in.
                        if (far && !from_retreat && self.mode != Mode::Tracking) || self.replan {
                            match self.plan(&bh) {
                                Ok(p) => {
                                    self.path = Some(p);
                                    (self.sigma, self.sigma_dot) = (0.0, 0.0);
                                    self.replan = false;
                                    let resumed = self.enter(Mode::Approaching);
                                    event = event.or(match p {
                                        Plan::Transit(t) => Some(Event::Transit(t.length())),
                                        Plan::Shell(_) => resumed,
                                    });
                                }
                                Err(r) => reason = Some(r),
                            }
                        } else {
                            event = event.or(self.enter(Mode::Tracking));
                        }
                    }
                    match (reason, self.mode, self.path) {
                        (Some(r), _, _) => {
                            self.clear_since = None;
                            event = event.or(self.enter(Mode::Holding(r)));
                            self.stand_still()
                        }
                        (None, Mode::Approaching, Some(Plan::Transit(t))) => {
                            // In joint space, the head's motion aside (the checks on every
                            // command still see it); the shell path follows from its end.
                            let p = &self.cfg.params;
                            let lag = |q: &[f64; 6], r: &[f64; 6]| {
                                (0..6).fold(0.0f64, |m, j| m.max((q[j] - r[j]).abs()))
                            };
                            let want = if lag(&self.q_cmd, &t.at(self.sigma)) < TRANSIT_LAG_RAD {
                                p.transit_speed_rad_s
                            } else {
                                0.0
                            };
                            (self.sigma, self.sigma_dot) = profile_step(
                                self.sigma,
                                self.sigma_dot,
                                t.length(),
                                want,
                                p.transit_accel_rad_s2,
                                self.dt,
                            );
                            if self.sigma >= t.length()
                                && lag(&self.q_cmd, t.end()) < TRANSIT_ARRIVED_RAD
                            {
                                self.path = None;
                                self.replan = true;
                            }
                            t.at(self.sigma)
                        }
                        (None, Mode::Approaching, Some(Plan::Shell(path))) => {
                            let target = self.path_target(&path, &bh);
                            rec.path = Some((self.sigma, path.length()));
                            let step = self.arm.ik_closest(
                                &target,
                                &self.q_cmd,
                                &Selection::tracking(self.cfg.params.joint_margin_rad),
                            );
                            match step {
                                Err(_) => {
                                    self.path = None;
                                    self.clear_since = None;
                                    event =
                                        event.or(self.enter(Mode::Holding(Reason::Unreachable)));
                                    self.stand_still()
                                }
                                Ok(c) if self.sigma >= path.length() => {
                                    // At the goal: hand over to tracking.
                                    self.path = None;
                                    event = event.or(self.enter(Mode::Tracking));
                                    c.joints
                                }
                                Ok(c) => c.joints,
                            }
                        }
                        _ => {
                            if margin < self.cfg.params.singularity_slow {
                                speed_fraction *=
                                    (margin / self.cfg.params.singularity_slow).max(0.1);
                            }
                            q
                        }
                    }
                }
            }
            (react, r, _, bh) => {
                // Hold (Plan included: hold now, go by a path once clear).
                if react == Reaction::Plan {
                    self.replan = true;
                }
                self.clear_since = None;
                self.path = None;
                match bh.and_then(|bh| self.give_way_in_hold(now, &bh, required)) {
                    Some((q, why)) => {
                        event = event.or(self.enter(Mode::Retreating(why)));
                        q
                    }
                    None => {
                        event = event.or(self.enter(Mode::Holding(r.unwrap_or(Reason::NoTracker))));
                        self.stand_still()
                    }
                }
            }
        };

        // Limits, then the safety filter: a command whose coil would come closer to the
        // predicted head than required is moved back along the approach axis by the deficit.
        let saved = (self.q_cmd, self.v_cmd, self.last_desired);
        self.giving_way = matches!(self.mode, Mode::Retreating(_));
        let mut q_next = self.limit(&desired, speed_fraction);
        if let Some(bh) = base_from_head
            && matches!(self.mode, Mode::Tracking | Mode::Retreating(_))
        {
            let max_standoff = self.cfg.params.max_standoff_m;
            let mut extra = 0.0;
            for _ in 0..FILTER_PASSES {
                let coil = self.head_from_coil_at(&q_next, &bh);
                let deficit = standoff_for(
                    &self.cfg.head,
                    &self.cfg.coil,
                    &coil,
                    required,
                    max_standoff,
                );
                if deficit <= 0.0 {
                    break;
                }
                extra += deficit;
                match self.retarget(&bh, extra, saved, &desired, speed_fraction) {
                    Some(q) => q_next = q,
                    None => break,
                }
            }
            rec.filtered_m = extra;
        }

        // The collision checks on the commanded motion (links, the coil's contact tolerance, the
        // approach rule), each answered by its reaction.
        let refused = base_from_head.and_then(|bh| {
            let prev = self.last_head.unwrap_or(bh);
            self.last_head = Some(bh);
            let approach_rule = !matches!(self.mode, Mode::Tracking | Mode::Retreating(_));
            self.check_motion(&saved.0, &q_next, &prev, &bh, approach_rule)
        });
        if let Some(r) = refused {
            let mut gave_way = false;
            if reaction(&r) == Reaction::Retreat
                && let Some(bh) = base_from_head
            {
                // The head comes into the coil: back off now, along the coil's axis (from the
                // goal when following it, else from where the coil is).
                if !matches!(self.mode, Mode::Tracking | Mode::Retreating(_)) {
                    self.anchor = self.head_from_coil_at(&saved.0, &bh);
                    self.standoff = 0.0;
                    self.path = None;
                }
                self.standoff = self.standoff.max(self.cfg.params.retreat_distance_m);
                self.giving_way = true;
                // The most the limits allow this cycle, even if that is not yet clear of the head
                // (holding instead would let the head push in further); only a link the retreat
                // would bring into the head stops it.
                if let Some(q) = self.retarget(&bh, 0.0, saved, &desired, speed_fraction)
                    && !matches!(
                        self.check_motion(&saved.0, &q, &bh, &bh, false),
                        Some(Reason::LinkCollision(..))
                    )
                {
                    q_next = q;
                    gave_way = true;
                    self.clear_since = None;
                    event = self.enter(Mode::Retreating(r)).or(event);
                }
            }
            if !gave_way {
                // Refuse: decelerate along the last command instead.
                (self.q_cmd, self.v_cmd, self.last_desired) = saved;
                let hold = self.stand_still();
                q_next = self.limit(&hold, speed_fraction);
                self.clear_since = None;
                // A hold outranks a resume decided earlier in the same cycle. A coil refused
                // near the head goes round by the shell when it resumes, never straight on.
                self.path = None;
                self.replan |= matches!(r, Reason::CoilCollision(_) | Reason::OffApproachAxis(_));
                event = self.enter(Mode::Holding(r)).or(event);
            }
        }
        if let Some(bh) = base_from_head {
            rec.clearance_m = self.cfg.coil.distance_below(
                &self.cfg.head,
                &self.head_from_coil_at(&q_next, &bh),
                CLEARANCE_EXACT_BELOW_M,
            );
        }
        self.q_cmd = q_next;
        rec.q_command = q_next;
        if let Ok(seq) = robot.servo(&q_next, &self.cfg.servo) {
            self.note_command(seq, now);
            self.servo_sent = true;
        }
        rec.mode = self.mode;
        rec.event = event;
        rec.command_delay_s = self.command_delay;
        rec
    }
}
