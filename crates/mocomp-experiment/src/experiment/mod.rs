//! The paper's two-robot experiment (its section VI), on the simulated world, in lockstep.
//!
//! A head robot U2 (UR5 by default) carries a head phantom whose marker the tracker sees; it
//! moves the phantom on a trajectory the controller does not know. A coil robot U1 (UR3) carries
//! the coil, which also carries a marker. Both are `mocomp-ursim` controllers on their own
//! loopback addresses, driven through mocomp's real RTDE client; the tracker model serves both
//! markers over real OpenIGTLink (TCP on loopback) to mocomp's real client. Everything runs on
//! one stepped clock: each tick the tracker acquires and sends, the controllers command, then both
//! simulators step, and every message is waited for, so a run is deterministic for its seed and
//! much faster than real time.
//!
//! As in the paper, the run starts with the initialisation: both robots are hand-eye calibrated
//! with the tracker (U1 gives `X1 = flange_from_coil`, `Y1 = base1_from_tracker`; U2 gives
//! `X2 = flange_from_head`), so calibration error is part of the result, and the goal is set from
//! the paper's `E2_T_E1,g` through those estimates:
//! `head_from_coil_goal = X2⁻¹ · E2_T_E1,g · X1`.
//! Then each controller compensates the same head trajectory with the same tracker noise:
//! - `paper`: a model of the original MATLAB pipeline. Every `period_s` it takes the newest
//!   tracker sample, computes the IK solution nearest by angle sum, and `compute_delay_s` later
//!   sends a point-to-point joint move (movej) to it. No prediction, no servoing
//!   ([`mocomp_control::baseline::PaperPipeline`]).
//! - `mocomp`: the compensation loop of `mocomp-control` at the robot's rate.
//!
//! Both are [`mocomp_control::Controller`]s: the experiment drives whichever it runs the same
//! way, one cycle and one command per robot period.
//!
//! The score is the paper's `d(t) = ‖E2_T_E1,g − E2_T_E1‖_F` (translation in mm), computed from the
//! simulators' true joints, with the translation and rotation errors of `E2_T_E1`.
//!
//! Its parts, one job each: the settings and their check (`config`), where the robots, the
//! tracker and the head stand (`scene`), the simulated rig started, moved and calibrated
//! (`rig`), one controller's run on it (`compensate`), the pace of each tick (`lockstep`), and
//! what a run records and how it is scored (`record`); the public run is here.

use mocomp_control::LoopConfig;
use mocomp_frontend::{Controls, Observer};
use mocomp_geom::nalgebra::Isometry3;
use std::time::{Duration, Instant};

mod compensate;
mod config;
mod lockstep;
mod record;
mod rig;
mod scene;

pub use config::{ExperimentConfig, PAPER_GOAL_E2_FROM_E1_MM, paper_goal};
use lockstep::{DriftWatch, Lockstep};
pub use record::{LoggedPulse, Record, Run, Stats};
use rig::Rig;
pub use scene::{Scene, build_scene, head_from_coil_design};
use scene::{calibration_backoff, touching_goal};

/// Sender timestamps are the stepped clock plus this (a timestamp of 0 means "unset").
const EPOCH_S: f64 = 1_000.0;

/// Device names.
const HEAD_DEVICE: &str = "HeadToTracker";
const COIL_DEVICE: &str = "CoilToTracker";

/// Something went wrong running the experiment.
#[derive(Debug, thiserror::Error)]
pub enum ExperimentError {
    /// A configuration value out of range.
    #[error("{0}")]
    Config(String),
    /// The dose cannot be planned for a goal.
    #[error(transparent)]
    Dose(#[from] mocomp_efield::DosePlanError),
    /// The paper's goal matrix is not a rigid transform.
    #[error("the goal E2_T_E1,g: {0}")]
    Goal(String),
    /// No placement of the robots reaches the goal.
    #[error("cannot place the robots: {0}")]
    Scene(String),
    /// A simulator or connection failed (its cause kept as the error's source).
    #[error("{what}{}", simulators_said(.simulators))]
    Io {
        /// What was being done.
        what: &'static str,
        /// What the simulators recorded meanwhile, when known.
        simulators: Option<String>,
        /// Why it failed.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// Something did not happen in time (a message, a state): the rig is hung.
    #[error("timed out waiting for {what}{}", seen.as_deref().map(|s| format!(" ({s})")).unwrap_or_default())]
    Timeout {
        /// What was waited for.
        what: &'static str,
        /// What was seen instead, when known.
        seen: Option<String>,
    },
    /// The calibration failed.
    #[error("calibration of {robot}: {detail}")]
    Calibration {
        /// Which robot.
        robot: &'static str,
        /// Why.
        detail: String,
    },
}

fn io(
    what: &'static str,
    e: impl Into<Box<dyn std::error::Error + Send + Sync>>,
) -> ExperimentError {
    ExperimentError::Io {
        what,
        simulators: None,
        source: e.into(),
    }
}

fn simulators_said(s: &Option<String>) -> String {
    s.as_deref()
        .map(|s| format!(" (simulators: {s})"))
        .unwrap_or_default()
}

/// Which controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Controller {
    /// The model of the paper's pipeline.
    Paper,
    /// mocomp's compensation loop.
    Mocomp,
    /// mocomp's loop knowing the head's true future, with no latency ([`crate::oracle`]): the
    /// bound.
    Oracle,
}

impl Controller {
    /// Every controller, in the order a full comparison runs them.
    pub const ALL: [Controller; 3] = [Self::Paper, Self::Mocomp, Self::Oracle];

    /// Its name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Self::Paper => "paper",
            Self::Mocomp => "mocomp",
            Self::Oracle => "oracle",
        }
    }

    /// The controller named `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }
}

/// The calibration of one robot against the tracker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationResult {
    /// Estimated flange_from_marker.
    pub flange_from_marker: Isometry3<f64>,
    /// Estimated base_from_tracker.
    pub base_from_tracker: Isometry3<f64>,
    /// Residual RMS, m and rad.
    pub residual: (f64, f64),
    /// Error of X against the truth, m and rad.
    pub x_error: (f64, f64),
    /// Error of Y against the truth, m and rad.
    pub y_error: (f64, f64),
    /// Pairs measured.
    pub pairs: usize,
}

/// The whole experiment's result.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Where everything was.
    pub scene: Scene,
    /// U1's calibration (coil robot).
    pub coil_calibration: CalibrationResult,
    /// U2's calibration (head robot).
    pub head_calibration: CalibrationResult,
    /// The goal the controllers used, head_from_coil (from the estimates).
    pub head_from_coil_goal: Isometry3<f64>,
    /// The head's peak speeds over the run, m/s and rad/s.
    pub head_peak_speed: (f64, f64),
    /// One run per controller, in the order run.
    pub runs: Vec<Run>,
}

/// What the experiment is doing, for a progress display.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Starting the simulators and connecting.
    Connecting,
    /// Calibrating the coil robot.
    CalibratingCoilRobot,
    /// Calibrating the head robot.
    CalibratingHeadRobot,
    /// Running a controller.
    Compensating(Controller),
}

impl std::fmt::Display for Phase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Connecting => f.write_str("starting the simulators"),
            Self::CalibratingCoilRobot => f.write_str("calibrating the coil robot"),
            Self::CalibratingHeadRobot => f.write_str("calibrating the head robot"),
            Self::Compensating(c) => write!(f, "compensating: {}", c.name()),
        }
    }
}

/// A front end watching the experiment as it runs (`mocomp demo --dashboard`, `--record`): each
/// controller's cycles are told to an observer, and the operator's hold and stop reach it; for a
/// console each run is paced in real time (one second of the stepped clock per second of the
/// wall clock; the record is the same as unpaced, the lockstep decides it).
pub struct Watch<'a> {
    /// The operator's requests: hold and resume (the `mocomp` controller's; the paper's pipeline
    /// has none), and stop (the run ends; the experiment then ends early).
    pub controls: &'a Controls,
    /// Paced in real time (a person watches), or as fast as the lockstep goes (a recording).
    pub real_time: bool,
    /// Makes the observer of one controller's run, given the loop configuration the experiment
    /// calibrated (its frames place the scene).
    pub observer: &'a mut dyn FnMut(Controller, &LoopConfig) -> Box<dyn Observer>,
}

impl std::fmt::Debug for Watch<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Watch").finish_non_exhaustive()
    }
}

/// One run's watching: its observer, the wall clock it is paced by (if it is), the hold passed
/// on.
struct Watching<'a> {
    controls: &'a Controls,
    observer: Box<dyn Observer>,
    wall0: Option<Instant>,
    held: bool,
}

/// How long the rig may go without doing what it was asked before it is called hung. The rig
/// runs in lockstep on a stepped clock, so the machine's speed changes no result, only how long
/// a tick takes: this catches a rig that stopped answering, not a slow machine (a 2-core machine
/// beside other work has kept the experiment's threads off its CPUs for seconds).
pub(crate) const RIG_PATIENCE: Duration = Duration::from_secs(60);

/// How long a wait spins before it sleeps between looks: a lockstep tick's answer comes within
/// microseconds, and a longer wait should leave the CPUs to the threads it waits for.
const SPIN_FIRST: Duration = Duration::from_millis(2);

/// Waits until `f` holds; fails naming `what` after [`RIG_PATIENCE`].
fn spin(what: &'static str, f: impl FnMut() -> bool) -> Result<(), ExperimentError> {
    spin_seen(what, f, || None)
}

/// [`spin`], saying what `seen` reports when it fails.
fn spin_seen(
    what: &'static str,
    f: impl FnMut() -> bool,
    seen: impl FnOnce() -> Option<String>,
) -> Result<(), ExperimentError> {
    wait_until(RIG_PATIENCE, what, f, seen)
}

/// The wait itself, its patience given, so a test can give a short one.
fn wait_until(
    patience: Duration,
    what: &'static str,
    mut f: impl FnMut() -> bool,
    seen: impl FnOnce() -> Option<String>,
) -> Result<(), ExperimentError> {
    let start = Instant::now();
    while !f() {
        let waited = start.elapsed();
        if waited > patience {
            return Err(ExperimentError::Timeout { what, seen: seen() });
        }
        if waited < SPIN_FIRST {
            std::thread::yield_now();
        } else {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    Ok(())
}

/// Runs the whole experiment: the scene, both calibrations, then each controller in `order`.
/// `progress` is told the phase and the fraction of it done.
pub fn run_experiment(
    cfg: &ExperimentConfig,
    order: &[Controller],
    progress: &mut dyn FnMut(Phase, f64),
) -> Result<Outcome, ExperimentError> {
    run_experiment_watched(cfg, order, progress, None)
}

/// [`run_experiment`], with a front end watching each controller's run in real time (see
/// [`Watch`]). A stop ends the runs early; the caller decides what to do with the outcome.
pub fn run_experiment_watched(
    cfg: &ExperimentConfig,
    order: &[Controller],
    progress: &mut dyn FnMut(Phase, f64),
    mut watch: Option<&mut Watch<'_>>,
) -> Result<Outcome, ExperimentError> {
    cfg.validate()?;
    let scene = build_scene(cfg)?;
    // On the scalp, the goal (for the controllers and for d) touches it; the scene stays as
    // placed for the paper's goal.
    let touching;
    let cfg = if cfg.on_scalp {
        let mut c = cfg.clone();
        c.goal_e2_from_e1 = touching_goal(cfg, &scene);
        touching = c;
        &touching
    } else {
        cfg
    };
    progress(Phase::Connecting, 0.0);
    let mut world = Rig::start(cfg, scene)?;
    progress(Phase::Connecting, 1.0);
    let coil_calibration = world.calibrate(true, cfg, progress)?;
    let head_calibration = world.calibrate(false, cfg, progress)?;
    // The goal through the estimates, as in the paper: head_from_coil = X2⁻¹ · E2_T_E1,g · X1.
    let head_from_coil_goal = head_calibration.flange_from_marker.inverse()
        * cfg.goal_e2_from_e1
        * coil_calibration.flange_from_marker;
    let period = cfg.coil_robot.spec().series.period_s();
    let mut loop_cfg = LoopConfig::new(
        coil_calibration.base_from_tracker,
        coil_calibration.flange_from_marker,
        head_from_coil_goal,
        period,
    );
    loop_cfg.params = cfg.loop_params;
    loop_cfg.predictor = cfg.predictor;
    (loop_cfg.servo.lookahead_s, loop_cfg.servo.gain) = cfg.servo;
    loop_cfg.head = cfg.loop_head.clone().unwrap_or_else(|| cfg.head.clone());
    loop_cfg.coil = cfg.coil.clone();
    let mut runs = Vec::with_capacity(order.len());
    for &c in order {
        runs.push(world.compensate(
            c,
            cfg,
            loop_cfg.clone(),
            coil_calibration.residual,
            progress,
            watch.as_deref_mut(),
        )?);
    }
    let head_peak_speed = cfg.motion.trajectory().peak_speeds(cfg.duration_s);
    Ok(Outcome {
        scene,
        coil_calibration,
        head_calibration,
        head_from_coil_goal,
        head_peak_speed,
        runs,
    })
}

#[cfg(test)]
mod error_tests {
    use super::*;

    #[test]
    fn a_failure_keeps_its_cause_as_the_source() {
        let cause = mocomp_ur::UrError::Closed {
            what: "RTDE at 127.0.0.2".into(),
        };
        let mut e = io("commanding the coil robot", cause);
        if let ExperimentError::Io { simulators, .. } = &mut e {
            *simulators = Some("0.016 s: program started".into());
        }
        assert_eq!(
            e.to_string(),
            "commanding the coil robot (simulators: 0.016 s: program started)"
        );
        let source = std::error::Error::source(&e).map(|s| s.is::<mocomp_ur::UrError>());
        assert_eq!(source, Some(true), "the cause is the source, not a string");
    }

    #[test]
    fn a_wait_ends_when_its_condition_holds_and_a_hung_one_says_what_it_saw() {
        let mut looks = 0;
        let held = wait_until(
            Duration::from_secs(60),
            "a state",
            || {
                looks += 1;
                looks > 3
            },
            || None,
        );
        assert!(held.is_ok());
        assert_eq!(looks, 4);
        let hung = wait_until(
            Duration::from_millis(5),
            "the tracker clients to connect",
            || false,
            || Some("the server accepted 1".into()),
        );
        let Err(e) = hung else {
            panic!("a condition that never holds must time out");
        };
        assert_eq!(
            e.to_string(),
            "timed out waiting for the tracker clients to connect (the server accepted 1)"
        );
    }
}
