//! One controller's run on the rig: the head played, the controller driven, each tick recorded.

use super::*;
use crate::head_drive::HeadPlayer;
use crate::oracle::{HeadTruth, OracleSource, TruthOracle};
use crate::session_plan::SessionPlan;
use mocomp_control::baseline::PaperPipeline;
use mocomp_control::{Compensator, LoopConfig};
use mocomp_frontend::Observer;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, PoseSource};
use mocomp_kin::Selection;
use mocomp_session::{JointHistory, Session, SessionParams};
use mocomp_sim::TrackerSim;
use mocomp_ur::{Robot, ServoParams};
use mocomp_ursim::Sim;
use std::sync::Arc;
use std::time::Instant;

impl Rig {
    /// Brings both robots back to their start and restarts the tracker (same seed), so each
    /// controller meets the same trajectory and the same noise.
    pub(super) fn reset(&mut self, cfg: &ExperimentConfig) -> Result<(), ExperimentError> {
        let (q1, q2) = (self.scene.q1_start, self.scene.q2_start);
        // A robot its own safety system stopped in the last run (the paper's pipeline pressed
        // the coil into the head past the force limit) is unlocked and its program restarted,
        // as an operator would before the next run.
        for (sim, robot) in [
            (&self.sim1, &mut self.robot1),
            (&self.sim2, &mut self.robot2),
        ] {
            if sim.with(|c| c.safety_mode()) == mocomp_ur::SafetyMode::ProtectiveStop {
                let reply = sim.with(|c| c.dashboard("unlock protective stop"));
                if !reply.starts_with("Protective stop releasing") {
                    return Err(io("unlocking a protective stop", reply));
                }
                sim.stepping_in_real_time(|| robot.restart_program())
                    .map_err(|e| io("restarting the control program after a protective stop", e))?;
            }
        }
        self.bump = None;
        // The coil out of the way while the head goes back, then in along its axis.
        self.coil_clear_of_head()?;
        self.move_to(false, &q2)?;
        self.move_to(true, &q1)?;
        self.idle(0.1)?;
        self.tracker = TrackerSim::new(cfg.tracker, 2);
        // The force sensor's noise from its start too: the simulator read it as many times as
        // the machine's load made it while the arms moved back and a program restarted.
        self.sensor
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .restart();
        self.t_base = self.clock.now_s();
        while self.head_source.latest().is_some() {}
        Ok(())
    }

    /// Plays `cfg`'s head motion from the start with the coil robot still (it is out of the
    /// head's way at its start, as every run begins), and returns the head robot's joints at
    /// every tick: the truth a run then meets, since the head robot's motion does not depend on
    /// the coil's. Half a second beyond the run's end, for the commands that act after it.
    pub(super) fn play_head(
        &mut self,
        cfg: &ExperimentConfig,
    ) -> Result<HeadTruth, ExperimentError> {
        self.reset(cfg)?;
        let mut player = self.head_player(cfg);
        let servo = ServoParams::for_period(self.period);
        let n = ((cfg.duration_s + 0.5) / self.period).round() as usize;
        let mut q = Vec::with_capacity(n + 1);
        q.push(self.q_now.1);
        let t0 = self.clock.now_s();
        for _ in 0..n {
            // The tracker keeps up as in any run (its clock and the clients' counts stay in
            // step; the next reset starts it afresh).
            self.track()?;
            let q2 = player.setpoint(self.clock.now_s() - t0);
            let (sim2, robot2) = (&self.sim2, &mut self.robot2);
            Self::sent(sim2, || robot2.servo(&q2, &servo).map(|_| ()))?;
            let (sim1, robot1) = (&self.sim1, &mut self.robot1);
            Self::sent(sim1, || robot1.keep_alive())?;
            self.advance()?;
            q.push(self.q_now.1);
        }
        Ok(HeadTruth::new(
            self.arm2,
            self.scene.world_from_tracker.inverse(),
            self.scene.e2_from_head,
            self.period,
            q,
        ))
    }

    /// The head robot's player of `cfg`'s motion from its start.
    pub(super) fn head_player(&self, cfg: &ExperimentConfig) -> HeadPlayer {
        HeadPlayer::new(
            cfg.motion.trajectory(),
            self.scene.world_from_head_rest,
            &self.scene.e2_from_head,
            self.arm2,
            self.scene.q2_start,
            self.period,
        )
    }

    /// Moves the coil robot back along its flange axis from its start (away from the head), as
    /// far as it reaches up to 20 cm, where the head robot's moves cannot reach it (10 cm was not
    /// enough for a UR10's calibration poses).
    pub(super) fn coil_clear_of_head(&mut self) -> Result<(), ExperimentError> {
        let q1 = self.scene.q1_start;
        let q = [0.2, 0.15, 0.1]
            .into_iter()
            .find_map(|back| {
                let clear = self.arm1.fk_flange(&q1) * Isometry3::translation(0.0, 0.0, -back);
                self.arm1
                    .ik_closest(&clear, &q1, &Selection::tracking(0.1))
                    .ok()
            })
            .ok_or_else(|| {
                io(
                    "moving the coil robot clear of the head",
                    "no pose 10 to 20 cm back along the flange axis within reach",
                )
            })?
            .joints;
        self.move_to(true, &q)
    }

    /// The simulators' recent events, for an error message.
    pub(super) fn events(&self) -> String {
        let last = |sim: &Sim, name: &str| {
            let (ev, _) = sim.with(|c| c.events());
            let n = ev.len().saturating_sub(3);
            ev[n..]
                .iter()
                .map(|e| format!("{name} {:.3} s: {}", e.time_s, e.text))
                .collect::<Vec<_>>()
        };
        let mut v = last(&self.sim1, "coil robot");
        v.extend(last(&self.sim2, "head robot"));
        v.join("; ")
    }

    /// One controller's run from the start positions; an error says what the simulators saw.
    pub(super) fn compensate(
        &mut self,
        controller: Controller,
        cfg: &ExperimentConfig,
        loop_cfg: LoopConfig,
        drift_sigma: (f64, f64),
        progress: &mut dyn FnMut(Phase, f64),
        watch: Option<&mut Watch<'_>>,
    ) -> Result<Run, ExperimentError> {
        self.compensate_inner(controller, cfg, loop_cfg, drift_sigma, progress, watch)
            .map_err(|e| match e {
                ExperimentError::Io { what, source, .. } => ExperimentError::Io {
                    what,
                    simulators: Some(self.events()),
                    source,
                },
                other => other,
            })
    }

    pub(super) fn compensate_inner(
        &mut self,
        controller: Controller,
        cfg: &ExperimentConfig,
        loop_cfg: LoopConfig,
        drift_sigma: (f64, f64),
        progress: &mut dyn FnMut(Phase, f64),
        watch: Option<&mut Watch<'_>>,
    ) -> Result<Run, ExperimentError> {
        // The oracle's knowledge: the head's whole run, played first.
        let truth = match controller {
            Controller::Oracle => Some(Arc::new(self.play_head(cfg)?)),
            _ => None,
        };
        self.reset(cfg)?;
        let watching = watch.map(|w| Watching {
            controls: w.controls,
            observer: (w.observer)(controller, &loop_cfg),
            wall0: w.real_time.then(Instant::now),
            held: false,
        });
        let t0 = self.clock.now_s();
        self.bump = cfg.tracker_bump.map(|(at, b)| (t0 + at, b));
        // The coil's marker seen by the tracker against where the robot and the calibration put
        // it (the loop's `flange_from_coil` is the coil marker's frame here).
        let drift = DriftWatch {
            base_from_tracker: loop_cfg.base_from_tracker,
            flange_from_marker: loop_cfg.flange_from_coil,
            q1: JointHistory::default(),
        };
        // The session: the plan's (the paper's pipeline has no goal to switch), or the gate and
        // the drift monitor alone on the run's goal.
        let plan = cfg
            .session
            .as_ref()
            .filter(|_| controller == Controller::Mocomp);
        let params = plan.map_or_else(SessionParams::default, |p| p.params);
        let session = Session::new(params, drift_sigma, 0);
        let goal_head_from_coil = loop_cfg.head_from_coil_goal;
        let head_servo = ServoParams::for_period(self.period);
        // The world's scalp, which the true coil is measured against.
        let (head, coil) = (cfg.head.clone(), loop_cfg.coil.clone());
        let loop_frames = (loop_cfg.base_from_tracker, loop_cfg.flange_from_coil);
        let (mut ctl, oracle_source) = self.controller(controller, truth, cfg, loop_cfg, t0);
        let n = (cfg.duration_s / self.period).round() as usize;
        let dose = dose_plans(cfg, plan, &goal_head_from_coil)?;
        let mut pace = Lockstep {
            dose,
            player: self.head_player(cfg),
            loop_frames,
            oracle_source,
            world: self,
            cfg,
            controller,
            t0,
            head_servo,
            head,
            coil,
            n,
            k: 0,
            t: t0,
            inputs: 0,
            records: Vec::with_capacity(n),
            progress,
            watching,
            drift,
            session,
            plan,
            goal_head_from_coil,
            pending_goal: None,
            next_attempt: 0,
            pulse_until: None,
            by_hand: false,
            gate_level: false,
            pulses: Vec::new(),
            withheld: 0,
        };
        // Compute time is the machine's, whatever clock the world steps on.
        let stopwatch = mocomp_geom::MonotonicClock::new();
        let driven = mocomp_control::drive(ctl.as_mut(), &mut pace, &stopwatch);
        if let Some(w) = pace.watching.as_mut() {
            // The run is over (or failed): a recording closes its part.
            w.observer.finish();
        }
        driven?;
        shut_gate(&mut pace)?;
        let (pulses, withheld) = (std::mem::take(&mut pace.pulses), pace.withheld);
        let head_lags = pace.player.lags(cfg.duration_s);
        let records = pace.records;
        progress(Phase::Compensating(controller), 1.0);
        let mut run = Run::new(controller, records, self.period);
        run.head_lags = head_lags;
        run.pulses = pulses;
        run.withheld_pulses = withheld;
        run.bump_detected_after_s = cfg.tracker_bump.and_then(|(at, _)| {
            run.records
                .iter()
                .find(|r| r.t >= at && matches!(r.drift, Some(mocomp_session::Drift::Invalid(..))))
                .map(|r| r.t - at)
        });
        Ok(run)
    }
}

impl Rig {
    /// The controller a run drives, and for the oracle the pose source that knows the head's
    /// true future.
    fn controller(
        &self,
        controller: Controller,
        truth: Option<Arc<HeadTruth>>,
        cfg: &ExperimentConfig,
        loop_cfg: LoopConfig,
        t0: f64,
    ) -> (Box<dyn mocomp_control::Controller>, Option<OracleSource>) {
        match (controller, truth) {
            (Controller::Oracle, Some(truth)) => {
                let oracle = TruthOracle { truth, t0 };
                // Its tracker is perfect: a still head gives identical samples, which from a
                // real tracker only a frozen stream does.
                let mut loop_cfg = loop_cfg;
                loop_cfg.params.frozen_samples = u32::MAX;
                let clock: Arc<dyn Clock> = self.clock.clone();
                let source = OracleSource::new(oracle.clone(), clock);
                (
                    Box::new(
                        Compensator::new(loop_cfg, self.arm1, self.period)
                            .with_head_oracle(Arc::new(oracle)),
                    ),
                    Some(source),
                )
            }
            (Controller::Mocomp | Controller::Oracle, _) => (
                Box::new(Compensator::new(loop_cfg, self.arm1, self.period)),
                None,
            ),
            (Controller::Paper, _) => (
                Box::new(PaperPipeline::new(cfg.paper, self.arm1, &loop_cfg)),
                None,
            ),
        }
    }
}

/// With a coil model, the dose's plans for the run's goal and the session's targets.
fn dose_plans(
    cfg: &ExperimentConfig,
    plan: Option<&SessionPlan>,
    goal_head_from_coil: &Isometry3<f64>,
) -> Result<Option<mocomp_efield::DosePlans>, ExperimentError> {
    Ok(cfg
        .dose
        .as_ref()
        .map(|model| {
            let targets: Vec<Isometry3<f64>> = plan
                .map(|p| p.targets.iter().map(|t| t.1).collect())
                .unwrap_or_default();
            mocomp_efield::DosePlans::new(
                model,
                cfg.head.shape(),
                Some(goal_head_from_coil),
                &targets,
            )
        })
        .transpose()?)
}

/// The run is over: the stimulator's trigger is shut again.
fn shut_gate(pace: &mut Lockstep<'_, '_>) -> Result<(), ExperimentError> {
    if pace.gate_level
        && let Some(bit) = pace.session.params().gate_output
    {
        let (robot1, sim1) = (&mut pace.world.robot1, &pace.world.sim1);
        let n = sim1.stats().inputs;
        robot1
            .set_digital_output(bit, false)
            .map_err(|e| io("shutting the gate output", e))?;
        spin("the gate output to arrive", || sim1.stats().inputs > n)?;
    }
    Ok(())
}
