//! The lockstep pace: each tick the tracker, the head robot, the session and the coil robot's
//! one command, in order, on the stepped clock.

use super::*;
use crate::head_drive::HeadPlayer;
use crate::oracle::OracleSource;
use crate::session_plan::SessionPlan;
use mocomp_control::drive::Requests;
use mocomp_control::{CycleRecord, Mode};
use mocomp_frontend::Observer;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{
    Clock, LengthUnit, PoseSource, frobenius_deviation, rotation_error, translation_error,
};
use mocomp_session::{JointHistory, PulseAt, Session};
use mocomp_ur::{Robot, ServoParams};
use std::time::{Duration, Instant};

/// The experiment's pace: a tick of the stepped clock per cycle. Before each cycle the tracker
/// acquires and sends and the head robot takes its next point; after it, the coil robot's
/// command is waited for, both simulators step, and the tick is scored.
pub(super) struct Lockstep<'a, 'p> {
    pub(super) world: &'a mut Rig,
    pub(super) cfg: &'a ExperimentConfig,
    pub(super) controller: Controller,
    /// The clock at the run's start.
    pub(super) t0: f64,
    pub(super) head_servo: ServoParams,
    pub(super) head: mocomp_control::HeadModel,
    pub(super) coil: mocomp_control::CoilModel,
    /// The head robot playing the head's motion.
    pub(super) player: HeadPlayer,
    /// The loop's calibration: `base_from_tracker` and `flange_from_coil`.
    pub(super) loop_frames: (Isometry3<f64>, Isometry3<f64>),
    /// The oracle's tracker, when the oracle runs: the true head, in place of the tracker's.
    pub(super) oracle_source: Option<OracleSource>,
    /// Ticks in all, and done.
    pub(super) n: usize,
    pub(super) k: usize,
    /// This tick's time.
    pub(super) t: f64,
    /// The coil robot's simulator's input count before this tick's cycle.
    pub(super) inputs: u64,
    pub(super) records: Vec<Record>,
    pub(super) progress: &'p mut dyn FnMut(Phase, f64),
    /// A front end watching, if any.
    pub(super) watching: Option<Watching<'a>>,
    /// The coil robot's recent joints for the drift monitor.
    pub(super) drift: DriftWatch,
    /// The session: gate, pulses, drift monitor.
    pub(super) session: Session,
    /// The session's script, if any.
    pub(super) plan: Option<&'a SessionPlan>,
    /// The run's goal (the target without a plan).
    pub(super) goal_head_from_coil: Isometry3<f64>,
    /// A target's goal for the loop's next cycle.
    pub(super) pending_goal: Option<Isometry3<f64>>,
    /// The stimulator's next try.
    pub(super) next_attempt: usize,
    /// The pulse input is high until this clock time.
    pub(super) pulse_until: Option<f64>,
    /// The pulse on the input was given by hand.
    pub(super) by_hand: bool,
    /// The gate output's level as last set.
    pub(super) gate_level: bool,
    pub(super) pulses: Vec<LoggedPulse>,
    pub(super) withheld: usize,
    /// The dose each tick, with a coil model.
    pub(super) dose: Option<mocomp_efield::DosePlans>,
}

impl Lockstep<'_, '_> {
    /// Before the coil robot's cycle, `tr` into the run: the plan's next target, and the
    /// stimulator (its pulse on the coil robot's input, two robot periods long).
    pub(super) fn session_tick(&mut self, tr: f64) -> Result<(), ExperimentError> {
        let Some(plan) = self.plan else {
            return Ok(());
        };
        let w = &*self.world;
        let due = plan.target_at(tr);
        if due != self.session.target() || (self.k == 0 && !plan.targets.is_empty()) {
            self.session.select(due);
            self.pending_goal = plan.targets.get(due).map(|t| t.1);
        }
        let Some(bit) = plan.params.pulse_input else {
            return Ok(());
        };
        if self.pulse_until.is_some_and(|until| self.t >= until) {
            w.sim1.with(|c| c.set_digital_input(bit, false));
            self.pulse_until = None;
        }
        while let Some(a) = plan.attempts.get(self.next_attempt).filter(|a| a.t_s <= tr) {
            self.next_attempt += 1;
            let gate_high = plan
                .params
                .gate_output
                .is_some_and(|g| w.sim1.with(|c| c.io().digital_outputs()) & (1 << g) != 0);
            if self.pulse_until.is_some() || (a.gated && !gate_high) {
                self.withheld += usize::from(a.gated);
                continue;
            }
            w.sim1.with(|c| c.set_digital_input(bit, true));
            self.pulse_until = Some(self.t + 2.0 * w.period);
            self.by_hand = !a.gated;
        }
        Ok(())
    }
}

/// Whose dose plan `target` (the session's selected one) is: a session target's, or the goal's
/// (no session, or one without targets of its own).
pub(super) fn dose_target(plan: Option<&SessionPlan>, target: usize) -> Option<usize> {
    plan.filter(|p| !p.targets.is_empty()).map(|_| target)
}

/// What the drift monitor needs: the calibration, and the coil robot's recent joints (a marker
/// sample is compared with the robot where it was when the sample was acquired).
pub(super) struct DriftWatch {
    pub(super) base_from_tracker: Isometry3<f64>,
    pub(super) flange_from_marker: Isometry3<f64>,
    pub(super) q1: JointHistory,
}

/// The truth at a cycle's time (the joints before this tick's step): the target selected, the
/// true coil, and the true coil against that target on the true head (m, rad).
pub(super) struct Truth {
    target: usize,
    true_coil: Isometry3<f64>,
    target_error: (f64, f64),
}

impl Lockstep<'_, '_> {
    /// The cycle's command taken by the coil robot's simulator, then both simulators stepped.
    fn step_world(&mut self, rec: &CycleRecord) -> Result<(), ExperimentError> {
        let w = &mut *self.world;
        if matches!(rec.mode, Mode::Faulted(_)) {
            w.robot1
                .keep_alive()
                .map_err(|e| io("commanding the coil robot", e))?;
        }
        let (sim1, inputs) = (&w.sim1, self.inputs);
        spin("a command to arrive", || sim1.stats().inputs > inputs)?;
        w.advance()
    }

    /// The drift monitor: every coil-marker sample against the robot at its acquisition; its
    /// verdict when it changed.
    fn watch_drift(&mut self) -> Option<mocomp_session::Drift> {
        let w = &mut *self.world;
        let d = &mut self.drift;
        d.q1.push(w.clock.now_s(), w.q_now.0);
        let mut drift = None;
        while let Some(s) = w.coil_source.latest() {
            if let (true, Some(q)) = (s.valid, d.q1.at(s.acquired_s)) {
                let tracked = d.base_from_tracker * s.tracker_from_marker;
                let robot = w.arm1.fk_flange(&q) * d.flange_from_marker;
                drift = self
                    .session
                    .marker(s.acquired_s, &tracked, &robot)
                    .or(drift);
            }
        }
        drift
    }

    fn truth(&self) -> Truth {
        let w = &*self.world;
        let target = self.session.target();
        let head_from_coil_target = self
            .plan
            .and_then(|p| p.targets.get(target))
            .map_or(self.goal_head_from_coil, |t| t.1);
        let true_coil = w.world_from_e1(&w.q_prev.0) * w.scene.e1_from_coil;
        let true_target =
            w.world_from_e2(&w.q_prev.1) * w.scene.e2_from_head * head_from_coil_target;
        let target_error = (
            (true_coil.translation.vector - true_target.translation.vector).norm(),
            true_coil.rotation.angle_to(&true_target.rotation),
        );
        Truth {
            target,
            true_coil,
            target_error,
        }
    }

    /// The session on this cycle: the gate (to the coil robot's output) and a pulse on its input
    /// (the state after this tick's step carries it), logged with its truth. Whether the gate
    /// is open.
    fn session_cycle(&mut self, rec: &CycleRecord, truth: &Truth) -> Result<bool, ExperimentError> {
        let w = &mut *self.world;
        let inputs = w.robot1.state().map(|s| s.digital_inputs);
        let step = self.session.cycle(rec, inputs);
        if let Some(p) = step.pulse {
            let true_head = w.world_from_e2(&w.q_prev.1) * w.scene.e2_from_head;
            let dose_target = dose_target(self.plan, truth.target);
            let dose_pct = self.dose.as_mut().map_or(f64::NAN, |d| {
                d.dose(dose_target, &(true_head.inverse() * truth.true_coil))
                    .pct
            });
            self.pulses.push(LoggedPulse {
                pulse: PulseAt {
                    t_s: p.t_s - self.t0,
                    ..p
                },
                truth: truth.target_error,
                by_hand: self.by_hand,
                dose_pct,
            });
        }
        if step.gate_open != self.gate_level
            && let Some(bit) = self.session.params().gate_output
        {
            let (robot1, sim1) = (&mut w.robot1, &w.sim1);
            let n = sim1.stats().inputs;
            robot1
                .set_digital_output(bit, step.gate_open)
                .map_err(|e| io("setting the gate output", e))?;
            // Taken before the next cycle's command is counted.
            spin("the gate output to arrive", || sim1.stats().inputs > n)?;
            self.gate_level = step.gate_open;
        }
        Ok(step.gate_open)
    }

    /// The tick's record: the score against the paper's goal after this tick's step, the coil's
    /// error in the loop's own frames for its split into prediction and execution
    /// ([`split_errors`]), its clearance, contact force and dose.
    fn record(
        &mut self,
        rec: &CycleRecord,
        drift: Option<mocomp_session::Drift>,
        truth: &Truth,
        gate_open: bool,
    ) {
        let w = &*self.world;
        let tr = self.t - self.t0;
        let e2 = w.world_from_e2(&w.q_now.1);
        let e1 = w.world_from_e1(&w.q_now.0);
        let actual = e2.inverse() * e1;
        let (base_from_tracker, flange_from_coil) = self.loop_frames;
        let tracker_from_head = w.scene.world_from_tracker.inverse() * e2 * w.scene.e2_from_head;
        let goal_coil = (base_from_tracker * tracker_from_head * rec.head_from_coil_goal)
            .translation
            .vector;
        let model_coil = (w.arm1.fk_flange(&w.q_now.0) * flange_from_coil)
            .translation
            .vector;
        let aimed_coil = match (rec.mode, rec.head_at_target) {
            (Mode::Tracking, Some((t, head))) => Some((
                t - self.t0,
                (base_from_tracker * head * rec.head_from_coil_goal)
                    .translation
                    .vector,
            )),
            _ => None,
        };
        let goal = self.cfg.goal_e2_from_e1;
        let head_from_coil = (e2 * w.scene.e2_from_head).inverse() * e1 * w.scene.e1_from_coil;
        let dose_target = dose_target(self.plan, truth.target);
        let dose_pct = self
            .dose
            .as_mut()
            .map_or(f64::NAN, |d| d.dose(dose_target, &head_from_coil).pct);
        self.records.push(Record {
            t: tr + w.period,
            d: frobenius_deviation(&goal, &actual, LengthUnit::Millimetre),
            translation_m: translation_error(&goal, &actual),
            rotation_rad: rotation_error(&goal, &actual),
            head_speed: self.player.trajectory().speed_at(tr + w.period),
            sample_age_s: rec.sample_age_s,
            horizon_s: rec.horizon_s,
            mode: rec.mode,
            event: rec.event,
            coil_clearance_m: self.coil.measured_distance(&self.head, &head_from_coil),
            contact_force_n: w.contact.force_n(&head_from_coil),
            drift,
            target: truth.target,
            target_error: truth.target_error,
            measured_error: rec.coil_error,
            gate_open,
            aimed_coil,
            goal_coil,
            model_coil,
            prediction_m: f64::NAN,
            execution_m: f64::NAN,
            standoff_m: rec.standoff_m + rec.filtered_m,
            dose_pct,
        });
    }
}

impl mocomp_control::drive::Pace for Lockstep<'_, '_> {
    type Error = ExperimentError;

    fn next_cycle(&mut self) -> Result<Option<f64>, ExperimentError> {
        if self.k >= self.n {
            return Ok(None);
        }
        if let Some(watching) = &self.watching {
            if watching.controls.stop_requested() {
                return Ok(None);
            }
            // Paced in real time: the tick is due when as much wall time has passed.
            if let Some(wall0) = watching.wall0 {
                let due =
                    wall0 + Duration::from_secs_f64((self.world.clock.now_s() - self.t0).max(0.0));
                if let Some(wait) = due.checked_duration_since(Instant::now()) {
                    std::thread::sleep(wait);
                }
            }
        }
        let w = &mut *self.world;
        w.track()?;
        self.t = w.clock.now_s();
        let tr = self.t - self.t0;
        // The head robot follows the trajectory.
        let q2 = self.player.setpoint(tr);
        let (robot2, servo) = (&mut w.robot2, &self.head_servo);
        Rig::sent(&w.sim2, || robot2.servo(&q2, servo).map(|_| ()))?;
        self.session_tick(tr)?;
        let w = &mut *self.world;
        // The coil robot's controller: one cycle, one command, taken by the simulator before
        // the clock moves on.
        self.inputs = w.sim1.stats().inputs;
        Ok(Some(self.t))
    }

    fn loop_io(&mut self) -> (&mut dyn Robot, &mut dyn PoseSource) {
        match &mut self.oracle_source {
            Some(oracle) => (&mut self.world.robot1, oracle),
            None => (&mut self.world.robot1, &mut self.world.head_source),
        }
    }

    fn cycle_done(&mut self, mut rec: CycleRecord) -> Result<(), ExperimentError> {
        // The dose a live system knows: the measured coil against the goal the loop holds
        // (what the gate judges and a pulse records; the run's score takes the true coil's).
        if let (Some(d), Some(coil)) = (self.dose.as_mut(), rec.coil_now) {
            let m = d.dose_at_goal(&rec.head_from_coil_goal, &coil);
            (rec.dose_v_per_m, rec.dose_pct) = (m.v_per_m, m.pct);
        }
        self.step_world(&rec)?;
        let drift = self.watch_drift();
        let truth = self.truth();
        let gate_open = self.session_cycle(&rec, &truth)?;
        self.record(&rec, drift, &truth, gate_open);
        if let Some(watching) = self.watching.as_mut() {
            watching.observer.cycle(&rec, 0.0);
            if let Some(e) = &rec.event {
                watching.observer.event(rec.t, e);
            }
        }
        if self.k.is_multiple_of(50) {
            (self.progress)(
                Phase::Compensating(self.controller),
                self.k as f64 / self.n as f64,
            );
        }
        self.k += 1;
        Ok(())
    }

    fn requests(&mut self) -> Requests {
        let hold = self.watching.as_mut().and_then(|watching| {
            let hold = watching.controls.hold();
            let changed = (hold != watching.held).then_some(hold);
            watching.held = hold;
            changed
        });
        Requests {
            hold,
            goal: self.pending_goal.take(),
            calibration_invalid: self.session.calibration_invalid(),
            ..Requests::default()
        }
    }
}
