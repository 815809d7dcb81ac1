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

use crate::calibration::MoveState;
use crate::driver::Requests;
use crate::head_drive::{HeadPlayer, Lag};
use crate::oracle::{HeadTruth, OracleSource, TruthOracle};
use crate::session_plan::SessionPlan;
use mocomp_calib::plan::{PlanOptions, plan};
use mocomp_calib::{Method, NoiseModel, SolveOptions, solve};
use mocomp_control::baseline::{PaperController, PaperPipeline};
use mocomp_control::{Compensator, CycleRecord, Event, LoopConfig, Mode};
use mocomp_frontend::{Controls, Observer};
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Translation3, UnitQuaternion, Vector3};
use mocomp_geom::{
    Clock, LengthUnit, PoseSource, SteppedClock, frobenius_deviation, iso_from_matrix_mm,
    rotation_error, translation_error,
};
use mocomp_igtl::client::{Client, ClientConfig, IgtlPoseSource, TimestampMode};
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use mocomp_kin::{Arm, Model, Selection};
use mocomp_session::{JointHistory, PulseAt, Session, SessionParams};
use mocomp_sim::HeadMotion;
use mocomp_sim::contact::{Contact, ContactParams};
use mocomp_sim::{TrackerModel, TrackerSim};
use mocomp_ur::{Robot, ServoParams, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimConfig, ToolLoad};
use std::net::IpAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

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
    /// Something did not happen in time (a message, a state).
    #[error("timed out waiting for {0}")]
    Timeout(&'static str),
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

/// The experiment's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct ExperimentConfig {
    /// The coil robot U1.
    pub coil_robot: Model,
    /// The head robot U2.
    pub head_robot: Model,
    /// U1's loopback address.
    pub coil_host: IpAddr,
    /// U2's loopback address.
    pub head_host: IpAddr,
    /// Compensation time per controller, s.
    pub duration_s: f64,
    /// The head's motion (unknown to the controllers).
    pub motion: HeadMotion,
    /// The tracker.
    pub tracker: TrackerModel,
    /// The `paper` controller.
    pub paper: PaperController,
    /// Calibration poses per robot.
    pub calibration_poses: usize,
    /// Tracker samples averaged per calibration pose.
    pub calibration_samples: usize,
    /// The goal between the end-effectors, `E2_T_E1,g` (metres).
    pub goal_e2_from_e1: Isometry3<f64>,
    /// Changes to the `mocomp` loop's defaults.
    pub loop_params: mocomp_control::LoopParams,
    /// The `mocomp` loop's predictor.
    pub predictor: mocomp_control::PredictorConfig,
    /// The `mocomp` loop's servoj lookahead (s) and gain.
    pub servo: (f64, f64),
    /// The head: the phantom's scalp (what the coil touches and is measured against) and,
    /// unless `loop_head` says otherwise, the controllers' head model.
    pub head: mocomp_control::HeadModel,
    /// The head model the controllers believe instead of `head` (the ellipsoid fitted to the
    /// phantom's scalp, say), while the world stays `head`.
    pub loop_head: Option<mocomp_control::HeadModel>,
    /// Where the paper's goal puts the coil on the head (`head_from_coil`, +z into the head):
    /// the phantom is mounted on the head robot's flange so that it does. [on top, 3 mm off the
    /// ellipsoid]
    pub coil_design: Isometry3<f64>,
    /// The controllers' coil model.
    pub coil: mocomp_control::CoilModel,
    /// The contact between the coil and the phantom's scalp (the controllers' head model), and
    /// the coil robot's force sensor, as the coil robot's simulated controller reads them.
    pub contact: ContactParams,
    /// On the scalp: the goal moved along the coil's axis until it touches; `mocomp` holds
    /// its contact force there (`force_sensing`, `contact_mode`), `paper` holds the pose.
    pub on_scalp: bool,
    /// The tracker is bumped during each controller's run: at `.0` s into it, the camera moves
    /// by `.1` in its own frame (`tracker_from_bumped`). The calibration no longer holds; the
    /// drift monitor ([`mocomp_session::drift`]) on the coil's marker should see it.
    pub tracker_bump: Option<(f64, Isometry3<f64>)>,
    /// A clinical session during each `mocomp` run: targets walked, the on-target gate on the
    /// coil robot's output, a stimulator pulsing its input (see [`SessionPlan`]).
    pub session: Option<SessionPlan>,
    /// The coil's field model: each tick's dose at the target against the planned one
    /// ([`Record::dose_pct`]), scored per controller ([`Run::dose_error_pct`]).
    pub dose: Option<mocomp_efield::DoseModel>,
}

/// The paper's goal between the end-effectors, `E2_T_E1,g` (translation in mm).
pub const PAPER_GOAL_E2_FROM_E1_MM: [[f64; 4]; 4] = [
    [0.8725, 0.159, 0.4619, 9.5626],
    [-0.4253, -0.2179, 0.8784, -160.5035],
    [0.2404, -0.9629, -0.1225, 412.4959],
    [0.0, 0.0, 0.0, 1.0],
];

/// The paper's goal as a rigid transform (metres).
pub fn paper_goal() -> Result<Isometry3<f64>, ExperimentError> {
    let rows = PAPER_GOAL_E2_FROM_E1_MM;
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    // Four decimals in the paper: the rotation is orthonormal to about 1e-3.
    iso_from_matrix_mm(&m, 5e-3).map_err(|e| ExperimentError::Goal(e.to_string()))
}

impl ExperimentConfig {
    /// Bumps the tracker `at_s` into each run: the camera shifts by `offset_m` along its x axis
    /// and turns by `angle_rad` about its z axis. Refused (naming the option) when a value is not
    /// finite or the time is outside the run.
    pub fn bump_tracker(
        &mut self,
        at_s: f64,
        offset_m: f64,
        angle_rad: f64,
    ) -> Result<(), ExperimentError> {
        if !(at_s.is_finite() && at_s >= 0.0 && at_s < self.duration_s) {
            return Err(ExperimentError::Config(format!(
                "--tracker-bump-at-s {at_s}: must be within the run (0 to {} s)",
                self.duration_s
            )));
        }
        if !(offset_m.is_finite() && angle_rad.is_finite()) {
            return Err(ExperimentError::Config(
                "--tracker-bump-mm, --tracker-bump-deg: must be finite".into(),
            ));
        }
        self.tracker_bump = Some((
            at_s,
            Isometry3::new(Vector3::x() * offset_m, Vector3::z() * angle_rad),
        ));
        Ok(())
    }

    /// Seeds the random motion (if the motion is random) and the tracker's noise.
    pub fn set_seed(&mut self, seed: u64) {
        self.tracker.seed = seed;
        if let HeadMotion::Random(r) = &mut self.motion {
            r.seed = seed;
        }
    }

    /// Checks the values the components do not check themselves; the error names the key as in
    /// the configuration file (see `mocomp_app::config`).
    pub fn validate(&self) -> Result<(), ExperimentError> {
        let bad = |m: String| Err(ExperimentError::Config(m));
        if let Some(plan) = &self.session {
            plan.params
                .validate()
                .map_err(|m| ExperimentError::Config(format!("session: {m}")))?;
            if plan.duration_s() > self.duration_s + 1e-9 {
                return bad(format!(
                    "session: {} targets of {} s do not fit the run's {} s",
                    plan.targets.len(),
                    plan.per_target_s,
                    self.duration_s
                ));
            }
        }
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= 3600.0) {
            return bad(format!(
                "experiment.duration_s = {}: must be in (0, 3600]",
                self.duration_s
            ));
        }
        if self.coil_host == self.head_host {
            return bad(format!(
                "robot.host = experiment.head_host = {}: the two robots need their own addresses",
                self.coil_host
            ));
        }
        if !(self.coil_host.is_loopback() && self.head_host.is_loopback()) {
            return bad(format!(
                "robot.host = {}, experiment.head_host = {}: the simulators listen on loopback addresses only",
                self.coil_host, self.head_host
            ));
        }
        // One stepped clock ticks both simulators at one rate.
        let (p1, p2) = (
            self.coil_robot.spec().series.period_s(),
            self.head_robot.spec().series.period_s(),
        );
        if p1 != p2 {
            return bad(format!(
                "robot.model = {}, experiment.head_robot = {}: both must be of one series (CB3, or e-Series), as the lockstep ticks both at one rate",
                self.coil_robot, self.head_robot
            ));
        }
        if !(3..=100).contains(&self.calibration_poses) {
            return bad(format!(
                "calibrate.poses = {}: must be in [3, 100]",
                self.calibration_poses
            ));
        }
        if !(1..=100).contains(&self.calibration_samples) {
            return bad(format!(
                "calibrate.samples_per_pose = {}: must be in [1, 100]",
                self.calibration_samples
            ));
        }
        let p = &self.paper;
        for (k, v, lo, hi) in [
            ("experiment.paper.period_s", p.period_s, 0.001, 10.0),
            (
                "experiment.paper.compute_delay_s",
                p.compute_delay_s,
                0.0,
                10.0,
            ),
            (
                "experiment.paper.joint_speed_rad_s",
                p.joint_speed_rad_s,
                0.01,
                3.0,
            ),
            (
                "experiment.paper.joint_accel_rad_s2",
                p.joint_accel_rad_s2,
                0.01,
                40.0,
            ),
        ] {
            if !(v.is_finite() && (lo..=hi).contains(&v)) {
                return bad(format!("{k} = {v}: must be in [{lo}, {hi}]"));
            }
        }
        self.motion
            .validate()
            .map_err(|e| ExperimentError::Config(format!("tracker.simulated.motion.{e}")))?;
        self.tracker
            .validate()
            .map_err(|e| ExperimentError::Config(format!("tracker.simulated.model.{e}")))?;
        self.loop_params
            .validate()
            .map_err(|e| ExperimentError::Config(format!("loop.{e}")))?;
        self.predictor
            .validate()
            .map_err(|e| ExperimentError::Config(format!("predictor.{e}")))?;
        Ok(())
    }
}

/// Where everything is (world = the head robot's base).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scene {
    /// The coil robot's base.
    pub world_from_base1: Isometry3<f64>,
    /// The tracker.
    pub world_from_tracker: Isometry3<f64>,
    /// The phantom's marker on U2's flange (true).
    pub e2_from_head: Isometry3<f64>,
    /// The coil (and its marker) on U1's flange (true).
    pub e1_from_coil: Isometry3<f64>,
    /// U1's joints at the goal, at the start.
    pub q1_start: [f64; 6],
    /// U2's joints at the head's rest pose.
    pub q2_start: [f64; 6],
    /// The head at rest, world_from_head.
    pub world_from_head_rest: Isometry3<f64>,
}

/// The head model's goal: the coil on top of the head (semi-axis 0.11 m), 3 mm off, +z into it.
pub fn head_from_coil_design() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.113),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    )
}

/// The paper's goal moved along the coil's axis until the coil touches the scalp (the head
/// model's surface, where the contact law starts to push).
fn touching_goal(cfg: &ExperimentConfig, scene: &Scene) -> Isometry3<f64> {
    let along = |s: f64| {
        cfg.goal_e2_from_e1
            * scene.e1_from_coil
            * Translation3::new(0.0, 0.0, s)
            * scene.e1_from_coil.inverse()
    };
    let head_from_coil =
        |goal: &Isometry3<f64>| scene.e2_from_head.inverse() * goal * scene.e1_from_coil;
    // The distance is exact along the normal and a lower bound elsewhere: a few steps close it.
    let mut s = 0.0;
    for _ in 0..8 {
        s += cfg.coil.distance(&cfg.head, &head_from_coil(&along(s)));
    }
    along(s)
}

/// An upright frame at `p` turned by `yaw` about the vertical.
fn upright(p: Vector3<f64>, yaw: f64) -> Isometry3<f64> {
    Isometry3::new(p, Vector3::z() * yaw)
}

/// A frame at `from` looking at `to` along +z.
fn look_at(from: Vector3<f64>, to: Vector3<f64>) -> Isometry3<f64> {
    let z = (to - from).normalize();
    let x = Vector3::z().cross(&z);
    let x = if x.norm() < 1e-6 {
        Vector3::x()
    } else {
        x.normalize()
    };
    let y = z.cross(&x);
    let r = mocomp_geom::nalgebra::Rotation3::from_basis_unchecked(&[x, y, z]);
    Isometry3::from_parts(
        Translation3::from(from),
        UnitQuaternion::from_rotation_matrix(&r),
    )
}

/// Of candidate placements (a frame, and the flange pose it asks of `arm`), the one whose IK
/// solution is farthest from a singularity (the first of equals): its margin, frame and joints.
fn best_placement(
    arm: &Arm,
    seed: &[f64; 6],
    select: &Selection,
    candidates: impl Iterator<Item = (Isometry3<f64>, Isometry3<f64>)>,
) -> Option<(f64, Isometry3<f64>, [f64; 6])> {
    let mut best: Option<(f64, Isometry3<f64>, [f64; 6])> = None;
    for (frame, flange) in candidates {
        if let Ok(c) = arm.ik_closest(&flange, seed, select) {
            let margin = arm.singularity(&c.joints).margin(arm.geometry());
            if best.as_ref().is_none_or(|b| margin > b.0) {
                best = Some((margin, frame, c.joints));
            }
        }
    }
    best
}

/// The least singularity margin ([`mocomp_kin::Singularity::margin`]) a placement may have.
const MIN_MARGIN: f64 = 0.05;

/// The least singularity margin of `arm` following `flanges` on the branch of `q`
/// (`-inf` where it cannot reach one).
fn margin_along(arm: &Arm, q: &[f64; 6], flanges: impl Iterator<Item = Isometry3<f64>>) -> f64 {
    let mut q = *q;
    let mut least = arm.singularity(&q).margin(arm.geometry());
    for f in flanges {
        match arm.ik_closest(&f, &q, &Selection::tracking(0.05)) {
            Ok(c) => {
                q = c.joints;
                least = least.min(arm.singularity(&q).margin(arm.geometry()));
            }
            Err(_) => return f64::NEG_INFINITY,
        }
    }
    least
}

/// The chosen placement, or why there is none (`task`: what the robot must do).
fn placed(
    best: Option<(f64, Isometry3<f64>, [f64; 6])>,
    robot: Model,
    task: &str,
) -> Result<(Isometry3<f64>, [f64; 6]), ExperimentError> {
    match best {
        None => Err(ExperimentError::Scene(format!(
            "the {robot} cannot {task} from anywhere tried"
        ))),
        Some((margin, _, _)) if margin < MIN_MARGIN => Err(ExperimentError::Scene(format!(
            "the {robot} can {task} only near a singularity"
        ))),
        Some((_, frame, q)) => Ok((frame, q)),
    }
}

/// Where a robot's calibration poses are centred, from its start flange: 10 cm back along the
/// flange axis (the coil away from the head).
fn calibration_backoff() -> Isometry3<f64> {
    Isometry3::translation(0.0, 0.0, -0.1)
}

/// Head poses along the motion at which a candidate placement of the coil robot is checked.
const MOTION_SAMPLES: u32 = 300;

/// Chooses the phantom's mounting from the paper's goal and the coil's design pose, then places
/// the head and both robots so that the start is well inside both arms' workspaces.
pub fn build_scene(cfg: &ExperimentConfig) -> Result<Scene, ExperimentError> {
    let arm1 = Arm::new(cfg.coil_robot);
    let arm2 = Arm::new(cfg.head_robot);
    // The coil 8 cm out along U1's flange axis; the phantom mounted so that the paper's goal puts
    // the coil on top of the head.
    let e1_from_coil = Isometry3::translation(0.0, 0.0, 0.08);
    let e2_from_head = cfg.goal_e2_from_e1 * e1_from_coil * cfg.coil_design.inverse();
    let seed = [0.0, -1.57, 1.57, -1.57, -1.57, 0.0];
    let select = Selection {
        limit_margin: 0.3,
        ..Selection::default()
    };
    let yaws = || (0..24).map(|k| f64::from(k) * std::f64::consts::TAU / 24.0);
    // The head upright in front of U2: search its yaw and place for U2's best start.
    let heads = yaws().flat_map(|yaw| {
        [
            (0.35, 0.55),
            (0.45, 0.45),
            (0.3, 0.7),
            (0.5, 0.6),
            (0.25, 0.85),
        ]
        .map(|(x, z)| {
            let head = upright(Vector3::new(x, 0.0, z), yaw);
            (head, head * e2_from_head.inverse())
        })
    });
    // Placed for its start; but a motion that leads the head robot out of reach or near a
    // singularity from there (a wandering recorded head) places it for the whole motion.
    let trajectory = cfg.motion.trajectory();
    let path = &trajectory;
    let flanges = move |head: &Isometry3<f64>| {
        let head = *head;
        (0..=MOTION_SAMPLES).map(move |k| {
            let t = cfg.duration_s * f64::from(k) / f64::from(MOTION_SAMPLES);
            head * path.rest_from_head(t) * e2_from_head.inverse()
        })
    };
    let best = best_placement(&arm2, &seed, &select, heads.clone())
        .filter(|(_, head, q)| margin_along(&arm2, q, flanges(head)) >= MIN_MARGIN)
        .or_else(|| {
            heads
                .filter_map(|(head, flange)| {
                    let q = arm2.ik_closest(&flange, &seed, &select).ok()?.joints;
                    // Its calibration goes round a centre backed off from the start.
                    let centre = arm2.fk_flange(&q) * calibration_backoff();
                    arm2.ik_closest(&centre, &q, &Selection::tracking(0.1))
                        .ok()?;
                    Some((margin_along(&arm2, &q, flanges(&head)), head, q))
                })
                .max_by(|a, b| a.0.total_cmp(&b.0))
        });
    let (world_from_head_rest, q2_start) = placed(best, cfg.head_robot, "hold the phantom")?;
    // U1 upright, beside the head: search its yaw, distance and height, for the start pose
    // farthest from a singularity over the whole head motion, its links clear of the head all
    // the way (the coil follows the head through all of it: a start chosen alone can put the
    // arm at its reach, where the elbow races, or a link beside the head).
    let world_from_e1 = world_from_head_rest * e2_from_head.inverse() * cfg.goal_e2_from_e1;
    let target = world_from_e1.translation.vector;
    let g = arm1.geometry();
    let reach = g.a2.abs() + g.a3.abs();
    let trajectory = cfg.motion.trajectory();
    // Along the motion: the head, and the coil robot's flange at the goal on it.
    let along_motion: Vec<(Isometry3<f64>, Isometry3<f64>)> = (0..=MOTION_SAMPLES)
        .map(|k| {
            let t = cfg.duration_s * f64::from(k) / f64::from(MOTION_SAMPLES);
            let head = world_from_head_rest * trajectory.rest_from_head(t);
            (head, head * e2_from_head.inverse() * cfg.goal_e2_from_e1)
        })
        .collect();
    // The loop's collision model: a placement whose arm would pass its links closer to the head
    // than the loop allows would make the loop hold, not follow.
    let (head_model, link_radius, clearance) = (
        &cfg.head,
        cfg.loop_params.link_radius_m,
        cfg.loop_params.link_clearance_m,
    );
    // Only whether each point clears: the exact distance (a descent through a 100 k-triangle
    // scalp's hierarchy) only where a bound cannot say so (most points are far from the head).
    let cutoff = link_radius + clearance + 1e-3;
    let links_clear = |base: &Isometry3<f64>, q: &[f64; 6], world_from_head: &Isometry3<f64>| {
        let head_from_base = world_from_head.inverse() * base;
        let f = arm1.link_frames(q);
        (1..6).all(|i| {
            (0..=4).all(|k| {
                let a = f[i - 1].translation.vector;
                let b = f[i].translation.vector;
                let p = mocomp_geom::nalgebra::Point3::from(a + (b - a) * (f64::from(k) / 4.0));
                head_model.distance_below(&(head_from_base * p), cutoff) - link_radius > clearance
            })
        })
    };
    let mut best: Option<(f64, Isometry3<f64>, [f64; 6])> = None;
    for yaw in yaws() {
        for r in [0.45, 0.6, 0.75] {
            for h in [-0.3, -0.15, 0.0, 0.15] {
                let offset = Vector3::new(yaw.cos(), yaw.sin(), 0.0) * r * reach;
                let base = upright(target - offset + Vector3::z() * h, yaw);
                let Ok(start) = arm1.ik_closest(&(base.inverse() * world_from_e1), &seed, &select)
                else {
                    continue;
                };
                // Its calibration goes round a centre backed off from the start: reachable on
                // the start's branch, or no calibration (a goal beside the ear turns the arm).
                let centre = arm1.fk_flange(&start.joints) * calibration_backoff();
                if arm1
                    .ik_closest(&centre, &start.joints, &Selection::tracking(0.1))
                    .is_err()
                {
                    continue;
                }
                // Follow the motion on the start's branch; the least margin on the way counts.
                let mut q = start.joints;
                let mut margin = arm1.singularity(&q).margin(arm1.geometry());
                for (head, e1) in &along_motion {
                    match arm1.ik_closest(&(base.inverse() * e1), &q, &Selection::tracking(0.05)) {
                        Ok(c) if links_clear(&base, &c.joints, head) => {
                            q = c.joints;
                            margin = margin.min(arm1.singularity(&q).margin(arm1.geometry()));
                        }
                        _ => margin = f64::NEG_INFINITY,
                    }
                }
                if best.as_ref().is_none_or(|b| margin > b.0) {
                    best = Some((margin, base, start.joints));
                }
            }
        }
    }
    let (world_from_base1, q1_start) = placed(best, cfg.coil_robot, "reach the goal")?;
    // The tracker 1.3 m from the head, above and in front, looking at it.
    let h = world_from_head_rest.translation.vector;
    let world_from_tracker = look_at(h + Vector3::new(0.9, 0.5, 0.8), h);
    Ok(Scene {
        world_from_base1,
        world_from_tracker,
        e2_from_head,
        e1_from_coil,
        q1_start,
        q2_start,
        world_from_head_rest,
    })
}

/// One tick of one controller's run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Record {
    /// Time since the controller started, s.
    pub t: f64,
    /// The paper's d, with translation in mm.
    pub d: f64,
    /// Translation error of E2_T_E1, m.
    pub translation_m: f64,
    /// Rotation error of E2_T_E1, rad.
    pub rotation_rad: f64,
    /// The head's true speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// Age of the newest tracker sample the controller used, s (NaN before the first).
    pub sample_age_s: f64,
    /// Time from the newest sample to when the command takes effect, as the controller
    /// predicted (mocomp) or as built into the pipeline (paper), s.
    pub horizon_s: f64,
    /// The controller's mode (paper: always tracking).
    pub mode: Mode,
    /// A safety event in this tick.
    pub event: Option<Event>,
    /// The true coil's signed distance to the head model, m (negative: inside the head).
    pub coil_clearance_m: f64,
    /// The force the true coil presses on the scalp with (the contact law's springs), N.
    pub contact_force_n: f64,
    /// The drift monitor's verdict when it changed this tick.
    pub drift: Option<mocomp_session::Drift>,
    /// The target selected (its index in the session's plan; 0 without one).
    pub target: usize,
    /// The true coil against the selected target on the true head at the cycle's time, m and
    /// rad (the truth the gate's measured error estimates).
    pub target_error: (f64, f64),
    /// The measured error the gate judged, m and rad (NaN without a head estimate).
    pub measured_error: (f64, f64),
    /// The gate after this tick's cycle.
    pub gate_open: bool,
    /// The coil the cycle's command aimed for (the goal on the head it predicted), in the loop's
    /// base frame, m, and the run time it was for, s. `None` without a prediction, or while not
    /// tracking.
    pub aimed_coil: Option<(f64, Vector3<f64>)>,
    /// The coil's goal on the true head at this tick, through the loop's own calibration, m.
    pub goal_coil: Vector3<f64>,
    /// The coil where the arm's joints put it at this tick, through the loop's own calibration,
    /// m.
    pub model_coil: Vector3<f64>,
    /// The prediction's share of the coil's error at this tick: the coil aimed for this time
    /// against the goal on the true head then, m (NaN where no command aimed for it).
    pub prediction_m: f64,
    /// The execution's share: the coil against the one aimed for this time, m (NaN likewise).
    pub execution_m: f64,
    /// How far the safety filter backed this tick's command off along the approach axis (the
    /// standoff it asked for, and this cycle's move back), m: part of the execution's share,
    /// on purpose.
    pub standoff_m: f64,
    /// The dose the true coil gives at the selected target, % of the planned (NaN without a
    /// coil model).
    pub dose_pct: f64,
}

/// A pulse the session logged, with the truth at its time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoggedPulse {
    /// As logged (its time on the run's clock, from the run's start).
    pub pulse: PulseAt,
    /// The true coil against the target then, m and rad.
    pub truth: (f64, f64),
    /// Given by hand (not through the gate).
    pub by_hand: bool,
    /// With a coil model: the dose the true coil gave the target, % of the planned (NaN
    /// without).
    pub dose_pct: f64,
}

/// Summary statistics of a series.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Stats {
    /// Root mean square.
    pub rms: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Maximum.
    pub max: f64,
}

impl Stats {
    /// Of `v` (NaN-free).
    pub fn of(v: &[f64]) -> Self {
        if v.is_empty() {
            return Self {
                rms: f64::NAN,
                p95: f64::NAN,
                max: f64::NAN,
            };
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let p95 = s[((s.len() - 1) as f64 * 0.95).round() as usize];
        Self {
            rms,
            p95,
            max: s[s.len() - 1],
        }
    }
}

/// One controller's result.
#[derive(Debug, Clone)]
pub struct Run {
    /// Which controller.
    pub controller: Controller,
    /// Every tick.
    pub records: Vec<Record>,
    /// d (translation in mm).
    pub d: Stats,
    /// Translation error, mm.
    pub translation_mm: Stats,
    /// Rotation error, degrees.
    pub rotation_deg: Stats,
    /// The true coil's least distance to the head model over the run, m (negative: inside).
    pub min_clearance_m: f64,
    /// Time the true coil spent inside the head model, s.
    pub inside_head_s: f64,
    /// The contact force, N.
    pub contact_force_n: Stats,
    /// With a tracker bump: how long after it the drift monitor called the calibration
    /// invalid, s (`None`: no bump, or never).
    pub bump_detected_after_s: Option<f64>,
    /// With a session: every pulse logged, in order.
    pub pulses: Vec<LoggedPulse>,
    /// With a session: the stimulator's gated tries the shut gate withheld.
    pub withheld_pulses: usize,
    /// Where the head robot could not follow the head's trace within its joint limits (it
    /// lagged, and caught up as soon as it could); the score is of the head it played.
    pub head_lags: Vec<Lag>,
    /// The prediction's share of the coil's error, mm, over the ticks a tracking command aimed
    /// for ([`Record::prediction_m`]).
    pub prediction_mm: Stats,
    /// The execution's share, mm, over the same ticks ([`Record::execution_m`]).
    pub execution_mm: Stats,
    /// With a coil model: the dose's error against the planned, |dose − planned| in % of the
    /// planned, over the ticks ([`Record::dose_pct`]).
    pub dose_error_pct: Option<Stats>,
}

impl Run {
    fn new(controller: Controller, mut records: Vec<Record>, period_s: f64) -> Self {
        split_errors(&mut records, period_s);
        let col = |f: &dyn Fn(&Record) -> f64| records.iter().map(f).collect::<Vec<f64>>();
        let finite = |f: &dyn Fn(&Record) -> f64| {
            records
                .iter()
                .map(f)
                .filter(|x| x.is_finite())
                .collect::<Vec<f64>>()
        };
        let dose = finite(&|r| (r.dose_pct - 100.0).abs());
        Self {
            dose_error_pct: (!dose.is_empty()).then(|| Stats::of(&dose)),
            prediction_mm: Stats::of(&finite(&|r| r.prediction_m * 1e3)),
            execution_mm: Stats::of(&finite(&|r| r.execution_m * 1e3)),
            min_clearance_m: records
                .iter()
                .map(|r| r.coil_clearance_m)
                .fold(f64::INFINITY, f64::min),
            inside_head_s: records.iter().filter(|r| r.coil_clearance_m < 0.0).count() as f64
                * period_s,
            controller,
            d: Stats::of(&col(&|r| r.d)),
            translation_mm: Stats::of(&col(&|r| r.translation_m * 1e3)),
            rotation_deg: Stats::of(&col(&|r| r.rotation_rad.to_degrees())),
            contact_force_n: Stats::of(&col(&|r| r.contact_force_n)),
            bump_detected_after_s: None,
            pulses: Vec::new(),
            withheld_pulses: 0,
            head_lags: Vec::new(),
            records,
        }
    }
}

/// Fills each tick's prediction and execution shares ([`crate::split`]).
fn split_errors(records: &mut [Record], period_s: f64) {
    let ticks: Vec<crate::split::Tick> = records
        .iter()
        .map(|r| crate::split::Tick {
            aimed: r.aimed_coil,
            goal: r.goal_coil,
            model: r.model_coil,
        })
        .collect();
    for (r, share) in records
        .iter_mut()
        .zip(crate::split::shares(&ticks, period_s))
    {
        (r.prediction_m, r.execution_m) = share.unwrap_or((f64::NAN, f64::NAN));
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

/// Spins until `f` holds or `limit` passes.
fn spin(
    limit: Duration,
    what: &'static str,
    mut f: impl FnMut() -> bool,
) -> Result<(), ExperimentError> {
    let end = Instant::now() + limit;
    while !f() {
        if Instant::now() > end {
            return Err(ExperimentError::Timeout(what));
        }
        std::thread::yield_now();
    }
    Ok(())
}

/// The experiment's rig in lockstep: two simulated robots (U1 with the coil, U2 with the head
/// phantom) and the tracker model serving both markers, on one stepped clock. (A live session's
/// robot and tracker are `mocomp_app::world::World`.)
struct Rig {
    clock: Arc<SteppedClock>,
    period: f64,
    sim1: Sim,
    sim2: Sim,
    robot1: UrRobot,
    robot2: UrRobot,
    arm1: Arm,
    arm2: Arm,
    scene: Scene,
    tracker: TrackerSim,
    server: Server,
    /// The head marker's client (the loop's source).
    head_client: Client,
    /// The coil marker's client (calibration).
    coil_client: Client,
    /// Their pose sources.
    head_source: IgtlPoseSource,
    coil_source: IgtlPoseSource,
    /// The tracker's time 0 on the clock (each controller's run restarts the tracker).
    t_base: f64,
    /// Joints at the previous and this tick (for the tracker's acquisition times between).
    q_prev: ([f64; 6], [f64; 6]),
    q_now: ([f64; 6], [f64; 6]),
    t_prev: f64,
    /// The phantom's head in the coil robot's base frame, for its simulated controller's
    /// contact (set before it steps, from the head robot's joints at the same tick).
    base1_from_head: Arc<Mutex<Isometry3<f64>>>,
    /// The contact law the coil robot's simulated force sensor reads (restarted with each run).
    sensor: Arc<Mutex<Contact>>,
    /// The contact law, for the true force each tick.
    contact: Contact,
    /// The tracker's bump during a run: from this clock time on, the camera is moved by it.
    bump: Option<(f64, Isometry3<f64>)>,
}

impl Rig {
    fn start(cfg: &ExperimentConfig, scene: Scene) -> Result<Self, ExperimentError> {
        let mut c1 = ControllerConfig::new(cfg.coil_robot);
        c1.initial_q = scene.q1_start;
        let base1_from_head = Arc::new(Mutex::new(
            scene.world_from_base1.inverse() * scene.world_from_head_rest,
        ));
        let sensor = Arc::new(Mutex::new(Contact::new(
            cfg.contact,
            cfg.head.clone(),
            cfg.coil.clone(),
            cfg.tracker.seed,
        )));
        let (head, law) = (Arc::clone(&base1_from_head), Arc::clone(&sensor));
        let tcp_from_coil = scene.e1_from_coil;
        c1.tool_load = Some(ToolLoad::new(move |t, base_from_tcp| {
            let base_from_head = *head
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            law.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
                .wrench(t, &(base_from_tcp * tcp_from_coil), &base_from_head)
        }));
        let mut c2 = ControllerConfig::new(cfg.head_robot);
        c2.initial_q = scene.q2_start;
        let mut s1 = SimConfig::new(c1, cfg.coil_host);
        s1.clock = mocomp_ursim::SimClock::Stepped;
        let mut s2 = SimConfig::new(c2, cfg.head_host);
        s2.clock = mocomp_ursim::SimClock::Stepped;
        let sim1 = Sim::start(s1).map_err(|e| io("starting the coil robot's simulator", e))?;
        let sim2 = Sim::start(s2).map_err(|e| io("starting the head robot's simulator", e))?;
        let period = cfg.coil_robot.spec().series.period_s();
        let clock = Arc::new(SteppedClock::new(0.0));
        // Connect both while stepping the simulators at most at real time (the client feeds the
        // program's watchdog on the machine's clock, so a faster simulator would stop a client
        // that a busy machine delayed for a few milliseconds; the clock stays at 0 meanwhile).
        // Both at once, and a simulator stops stepping once its robot is connected: a connected
        // robot whose program is not fed would stop on its watchdog.
        let done = [AtomicBool::new(false), AtomicBool::new(false)];
        let slowest = period.max(cfg.head_robot.spec().series.period_s());
        let (r1, r2) = std::thread::scope(|s| {
            s.spawn(|| {
                while !(done[0].load(Ordering::Relaxed) && done[1].load(Ordering::Relaxed)) {
                    if !done[0].load(Ordering::Relaxed) {
                        sim1.step();
                    }
                    if !done[1].load(Ordering::Relaxed) {
                        sim2.step();
                    }
                    std::thread::sleep(Duration::from_secs_f64(slowest));
                }
            });
            let c: Arc<dyn Clock> = clock.clone();
            let c2 = Arc::clone(&c);
            let h2 = s.spawn(|| {
                let r = UrRobot::connect(sim2.ur_config(), c2);
                done[1].store(true, Ordering::Relaxed);
                r
            });
            let r1 = UrRobot::connect(sim1.ur_config(), c);
            done[0].store(true, Ordering::Relaxed);
            let r2 = h2.join();
            done[1].store(true, Ordering::Relaxed);
            (r1, r2)
        });
        // A failed connection says what the simulator saw.
        let events = |sim: &Sim| {
            let (ev, _) = sim.with(|c| c.events());
            ev.iter()
                .map(|e| format!("{:.3} s {}", e.time_s, e.text))
                .collect::<Vec<_>>()
                .join("; ")
        };
        let robot1 = r1.map_err(|e| ExperimentError::Io {
            what: "connecting to the coil robot",
            simulators: Some(events(&sim1)),
            source: Box::new(e),
        })?;
        let r2 = r2.map_err(|_| io("connecting to the head robot", "the thread panicked"))?;
        let robot2 = r2.map_err(|e| ExperimentError::Io {
            what: "connecting to the head robot",
            simulators: Some(events(&sim2)),
            source: Box::new(e),
        })?;
        let server = Server::bind("127.0.0.1:0", ServerConfig::default())
            .map_err(|e| io("starting the tracker's OpenIGTLink server", e))?;
        let client = |device: &str| {
            let mut c = ClientConfig::new(&server.local_addr().to_string());
            c.device = Some(device.to_string());
            c.timestamps = TimestampMode::Known(-EPOCH_S);
            Client::start(c, clock.clone())
        };
        let head_client = client(HEAD_DEVICE);
        let coil_client = client(COIL_DEVICE);
        spin(
            Duration::from_secs(5),
            "the tracker clients to connect",
            || server.client_count() == 2,
        )?;
        let q = (scene.q1_start, scene.q2_start);
        let mut w = Self {
            clock,
            period,
            sim1,
            sim2,
            robot1,
            robot2,
            arm1: Arm::new(cfg.coil_robot),
            arm2: Arm::new(cfg.head_robot),
            scene,
            tracker: TrackerSim::new(cfg.tracker, 2),
            server,
            head_source: head_client.pose_source(),
            coil_source: coil_client.pose_source(),
            head_client,
            coil_client,
            t_base: 0.0,
            q_prev: q,
            q_now: q,
            t_prev: 0.0,
            base1_from_head,
            sensor,
            contact: Contact::new(cfg.contact, cfg.head.clone(), cfg.coil.clone(), 0),
            bump: None,
        };
        // One step so the states carry the stepped clock's time.
        w.advance()?;
        Ok(w)
    }

    fn world_from_e1(&self, q1: &[f64; 6]) -> Isometry3<f64> {
        self.scene.world_from_base1 * self.arm1.fk_flange(q1)
    }

    fn world_from_e2(&self, q2: &[f64; 6]) -> Isometry3<f64> {
        self.arm2.fk_flange(q2)
    }

    /// The tracker acquires what is due and sends what its latency releases; returns when both
    /// clients have received it.
    fn track(&mut self) -> Result<(), ExperimentError> {
        let now = self.clock.now_s();
        let base = self.t_base;
        let (t0, t1) = (self.t_prev - base, now - base);
        let (qa, qb) = (self.q_prev, self.q_now);
        let lerp = |a: &[f64; 6], b: &[f64; 6], t: f64| {
            let s = if t1 > t0 {
                ((t - t0) / (t1 - t0)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let mut q = [0.0; 6];
            for i in 0..6 {
                q[i] = a[i] + (b[i] - a[i]) * s;
            }
            q
        };
        let unbumped = self.scene.world_from_tracker.inverse();
        let bump = self.bump;
        let (arm1, arm2, scene) = (self.arm1, self.arm2, self.scene);
        let mut truth = |marker: usize, t: f64| {
            // The camera as it stood when the sample was acquired.
            let tracker_from_world = match bump {
                Some((at, b)) if t + base >= at => (scene.world_from_tracker * b).inverse(),
                _ => unbumped,
            };
            Some(match marker {
                0 => {
                    tracker_from_world * arm2.fk_flange(&lerp(&qa.1, &qb.1, t)) * scene.e2_from_head
                }
                _ => {
                    tracker_from_world
                        * scene.world_from_base1
                        * arm1.fk_flange(&lerp(&qa.0, &qb.0, t))
                        * scene.e1_from_coil
                }
            })
        };
        let before = (
            self.head_client.counters().transforms,
            self.coil_client.counters().transforms,
        );
        let mut sent = 0u64;
        let server = &self.server;
        self.tracker.step(now - base, &mut truth, &mut |o| {
            let device = if o.marker == 0 {
                HEAD_DEVICE
            } else {
                COIL_DEVICE
            };
            let ts = Timestamp::from_secs_f64(o.acquired_s + base + EPOCH_S);
            if let Ok(m) = Message::transform(device, &o.tracker_from_marker, ts) {
                let status = if o.valid { "OK" } else { "INVALID" };
                server.send(&m.with_metadata(vec![MetaEntry::text("TransformStatus", status)]));
                sent += 1;
            }
        });
        if sent > 0 {
            let (h, c) = (&self.head_client, &self.coil_client);
            spin(Duration::from_secs(5), "tracker messages", || {
                h.counters().transforms >= before.0 + sent
                    && c.counters().transforms >= before.1 + sent
            })?;
        }
        Ok(())
    }

    /// Waits until both simulators have taken this tick's commands, advances the clock one
    /// period, steps both and waits for their new states.
    fn advance(&mut self) -> Result<(), ExperimentError> {
        let n = (self.robot1.state_count(), self.robot2.state_count());
        self.t_prev = self.clock.now_s();
        self.clock.advance(self.period);
        // The head robot first: the coil robot's contact needs where the head is at this tick.
        self.sim2.step();
        let q2 = self.sim2.with(|c| c.q());
        let base1_from_head = self.scene.world_from_base1.inverse()
            * self.arm2.fk_flange(&q2)
            * self.scene.e2_from_head;
        *self
            .base1_from_head
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = base1_from_head;
        self.sim1.step();
        let (r1, r2) = (&self.robot1, &self.robot2);
        spin(Duration::from_secs(5), "the robots' states", || {
            r1.state_count() > n.0 && r2.state_count() > n.1
        })?;
        self.q_prev = self.q_now;
        if let (Some(a), Some(b)) = (self.robot1.state(), self.robot2.state()) {
            self.q_now = (a.actual_q, b.actual_q);
        }
        Ok(())
    }

    /// Sends a command on a robot and waits until its simulator has it.
    fn sent(
        sim: &Sim,
        f: impl FnOnce() -> Result<(), mocomp_ur::UrError>,
    ) -> Result<(), ExperimentError> {
        let inputs = sim.stats().inputs;
        f().map_err(|e| io("commanding a robot", e))?;
        spin(Duration::from_secs(5), "a command to arrive", || {
            sim.stats().inputs > inputs
        })
    }

    /// Moves one robot (U1 if `coil`) to `q` with movej while the other keeps still, ticking
    /// until the move has arrived ([`crate::calibration::move_state`]).
    fn move_to(&mut self, coil: bool, q: &[f64; 6]) -> Result<(), ExperimentError> {
        let start = self.clock.now_s();
        let mut seq: Option<i32> = None;
        loop {
            self.track()?;
            let (mover, other, sim_m, sim_o) = if coil {
                (&mut self.robot1, &mut self.robot2, &self.sim1, &self.sim2)
            } else {
                (&mut self.robot2, &mut self.robot1, &self.sim2, &self.sim1)
            };
            let sent = match seq {
                Some(n) => {
                    Self::sent(sim_m, || mover.keep_alive())?;
                    n
                }
                None => {
                    let mut n = 0;
                    Self::sent(sim_m, || {
                        n = mover.move_joints(q, 2.0, 4.0)?;
                        Ok(())
                    })?;
                    seq = Some(n);
                    n
                }
            };
            Self::sent(sim_o, || other.keep_alive())?;
            self.advance()?;
            let s = if coil {
                self.robot1.state()
            } else {
                self.robot2.state()
            };
            if let Some(s) = s {
                if let Some(f) = s.fault() {
                    return Err(io("a calibration move", f.to_string()));
                }
                match crate::calibration::move_state(&s, q, sent) {
                    MoveState::Arrived => return Ok(()),
                    MoveState::Away => {
                        return Err(io(
                            "a calibration move",
                            "the move ended away from its target",
                        ));
                    }
                    MoveState::Moving => {}
                }
            }
            if self.clock.now_s() - start > 30.0 {
                return Err(ExperimentError::Timeout("a calibration move"));
            }
        }
    }

    /// Ticks for `seconds` with both robots still.
    fn idle(&mut self, seconds: f64) -> Result<(), ExperimentError> {
        let end = self.clock.now_s() + seconds;
        while self.clock.now_s() < end - 1e-9 {
            self.track()?;
            Self::sent(&self.sim1, || self.robot1.keep_alive())?;
            Self::sent(&self.sim2, || self.robot2.keep_alive())?;
            self.advance()?;
        }
        Ok(())
    }

    /// Hand-eye calibration of one robot against the tracker: the planner's poses around its
    /// start, `samples` averaged at each, solved with the refined method.
    fn calibrate(
        &mut self,
        coil: bool,
        cfg: &ExperimentConfig,
        progress: &mut dyn FnMut(Phase, f64),
    ) -> Result<CalibrationResult, ExperimentError> {
        let (arm, q0, name, phase) = if coil {
            (
                self.arm1,
                self.scene.q1_start,
                "the coil robot",
                Phase::CalibratingCoilRobot,
            )
        } else {
            (
                self.arm2,
                self.scene.q2_start,
                "the head robot",
                Phase::CalibratingHeadRobot,
            )
        };
        let calib_err = |detail: String| ExperimentError::Calibration {
            robot: name,
            detail,
        };
        if !coil {
            // The phantom turns and shifts around its start: the coil must not be in its way
            // (it was, unseen, until the coil's contact with the scalp was simulated).
            self.coil_clear_of_head()
                .map_err(|e| calib_err(format!("moving the coil robot clear: {e}")))?;
        }
        // Around the start, backed off along the flange axis (the coil away from the head).
        let center = arm.fk_flange(&q0) * calibration_backoff();
        let current = arm
            .ik_closest(&center, &q0, &Selection::tracking(0.1))
            .map_err(|e| calib_err(format!("the centre pose: {e}")))?
            .joints;
        let mut o = PlanOptions::new(cfg.calibration_poses, center, current);
        o.translation_spread_m = 0.06;
        o.rotation_range_rad = (12f64.to_radians(), 30f64.to_radians());
        let poses = plan(&arm, &o).map_err(|e| calib_err(e.to_string()))?;
        let n = poses.len() as f64;
        let mut station = CalibrationStation { world: self, coil };
        let got = crate::calibration::collect(
            &mut station,
            &arm,
            &poses,
            &q0,
            0.05,
            cfg.calibration_samples,
            &mut |i, _| progress(phase, (i + 1) as f64 / n),
        )?;
        if !got.missed.is_empty() {
            return Err(calib_err(format!(
                "no marker samples at pose(s) {:?}",
                got.missed
            )));
        }
        let pairs = got.pairs;
        let noise = NoiseModel {
            tracker_translation_m: cfg.tracker.noise_m.max(1e-6),
            tracker_rotation_rad: cfg.tracker.noise_rad.max(1e-6),
            robot_translation_m: 1e-5,
            robot_rotation_rad: 1e-5,
        };
        let c = solve(
            &pairs,
            &SolveOptions {
                method: Method::Refined,
                noise,
                reject_outliers: true,
            },
        )
        .map_err(|e| calib_err(e.to_string()))?;
        let (true_x, true_y) = if coil {
            (
                self.scene.e1_from_coil,
                self.scene.world_from_base1.inverse() * self.scene.world_from_tracker,
            )
        } else {
            (self.scene.e2_from_head, self.scene.world_from_tracker)
        };
        let err = |a: &Isometry3<f64>, b: &Isometry3<f64>| {
            (translation_error(a, b), rotation_error(a, b))
        };
        Ok(CalibrationResult {
            flange_from_marker: c.flange_from_marker,
            base_from_tracker: c.base_from_tracker,
            residual: (c.rms_mm * 1e-3, c.rms_deg.to_radians()),
            x_error: err(&c.flange_from_marker, &true_x),
            y_error: err(&c.base_from_tracker, &true_y),
            pairs: pairs.len(),
        })
    }
}

/// One robot of the experiment's world as a calibration station, in lockstep.
struct CalibrationStation<'a> {
    world: &'a mut Rig,
    /// U1 (the coil robot) if true, else U2.
    coil: bool,
}

impl crate::calibration::Station for CalibrationStation<'_> {
    type Error = ExperimentError;

    fn move_to(&mut self, q: &[f64; 6]) -> Result<(), ExperimentError> {
        self.world.move_to(self.coil, q)
    }

    fn settle(&mut self, seconds: f64) -> Result<(), ExperimentError> {
        self.world.idle(seconds)
    }

    /// The joints are the simulator's at the first sample (the arm is still); a marker unseen
    /// for 5 s of simulated time is not seen.
    fn measure(
        &mut self,
        samples: usize,
    ) -> Result<Option<crate::calibration::Measurement>, ExperimentError> {
        let w = &mut *self.world;
        let after = w.clock.now_s();
        let mut seen = Vec::new();
        let mut qs = Vec::new();
        while seen.len() < samples {
            w.idle(w.period)?;
            let s = if self.coil {
                w.coil_source.latest()
            } else {
                w.head_source.latest()
            };
            if let Some(s) = s
                && s.valid
                && s.acquired_s > after
            {
                seen.push(s.tracker_from_marker);
                qs.push(if self.coil { w.q_now.0 } else { w.q_now.1 });
            }
            if w.clock.now_s() - after > 5.0 {
                return Ok(None);
            }
        }
        let Some(&q) = qs.first() else {
            return Ok(None);
        };
        let marker =
            mocomp_geom::average(&seen, None).map_err(|e| io("averaging the marker samples", e))?;
        Ok(Some((q, marker)))
    }
}

impl Rig {
    /// Brings both robots back to their start and restarts the tracker (same seed), so each
    /// controller meets the same trajectory and the same noise.
    fn reset(&mut self, cfg: &ExperimentConfig) -> Result<(), ExperimentError> {
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
    fn play_head(&mut self, cfg: &ExperimentConfig) -> Result<HeadTruth, ExperimentError> {
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
    fn head_player(&self, cfg: &ExperimentConfig) -> HeadPlayer {
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
    fn coil_clear_of_head(&mut self) -> Result<(), ExperimentError> {
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
    fn events(&self) -> String {
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
    fn compensate(
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

    fn compensate_inner(
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
        let mut oracle_source = None;
        let mut ctl: Box<dyn mocomp_control::Controller> = match (controller, truth) {
            (Controller::Oracle, Some(truth)) => {
                let oracle = TruthOracle { truth, t0 };
                // Its tracker is perfect: a still head gives identical samples, which from a
                // real tracker only a frozen stream does.
                let mut loop_cfg = loop_cfg;
                loop_cfg.params.frozen_samples = u32::MAX;
                let clock: Arc<dyn Clock> = self.clock.clone();
                oracle_source = Some(OracleSource::new(oracle.clone(), clock));
                Box::new(
                    Compensator::new(loop_cfg, self.arm1, self.period)
                        .with_head_oracle(Arc::new(oracle)),
                )
            }
            (Controller::Mocomp | Controller::Oracle, _) => {
                Box::new(Compensator::new(loop_cfg, self.arm1, self.period))
            }
            (Controller::Paper, _) => Box::new(PaperPipeline::new(cfg.paper, self.arm1, &loop_cfg)),
        };
        let n = (cfg.duration_s / self.period).round() as usize;
        let dose = cfg
            .dose
            .as_ref()
            .map(|model| {
                let targets: Vec<Isometry3<f64>> = plan
                    .map(|p| p.targets.iter().map(|t| t.1).collect())
                    .unwrap_or_default();
                mocomp_efield::DosePlans::new(
                    model,
                    cfg.head.shape(),
                    Some(&goal_head_from_coil),
                    &targets,
                )
            })
            .transpose()?;
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
        let driven = crate::driver::drive(ctl.as_mut(), &mut pace);
        if let Some(w) = pace.watching.as_mut() {
            // The run is over (or failed): a recording closes its part.
            w.observer.finish();
        }
        driven?;
        if pace.gate_level
            && let Some(bit) = pace.session.params().gate_output
        {
            // The run is over: the stimulator's trigger is shut again.
            let (robot1, sim1) = (&mut pace.world.robot1, &pace.world.sim1);
            let n = sim1.stats().inputs;
            robot1
                .set_digital_output(bit, false)
                .map_err(|e| io("shutting the gate output", e))?;
            spin(Duration::from_secs(5), "the gate output to arrive", || {
                sim1.stats().inputs > n
            })?;
        }
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

/// The experiment's pace: a tick of the stepped clock per cycle. Before each cycle the tracker
/// acquires and sends and the head robot takes its next point; after it, the coil robot's
/// command is waited for, both simulators step, and the tick is scored.
struct Lockstep<'a, 'p> {
    world: &'a mut Rig,
    cfg: &'a ExperimentConfig,
    controller: Controller,
    /// The clock at the run's start.
    t0: f64,
    head_servo: ServoParams,
    head: mocomp_control::HeadModel,
    coil: mocomp_control::CoilModel,
    /// The head robot playing the head's motion.
    player: HeadPlayer,
    /// The loop's calibration: `base_from_tracker` and `flange_from_coil`.
    loop_frames: (Isometry3<f64>, Isometry3<f64>),
    /// The oracle's tracker, when the oracle runs: the true head, in place of the tracker's.
    oracle_source: Option<OracleSource>,
    /// Ticks in all, and done.
    n: usize,
    k: usize,
    /// This tick's time.
    t: f64,
    /// The coil robot's simulator's input count before this tick's cycle.
    inputs: u64,
    records: Vec<Record>,
    progress: &'p mut dyn FnMut(Phase, f64),
    /// A front end watching, if any.
    watching: Option<Watching<'a>>,
    /// The coil robot's recent joints for the drift monitor.
    drift: DriftWatch,
    /// The session: gate, pulses, drift monitor.
    session: Session,
    /// The session's script, if any.
    plan: Option<&'a SessionPlan>,
    /// The run's goal (the target without a plan).
    goal_head_from_coil: Isometry3<f64>,
    /// A target's goal for the loop's next cycle.
    pending_goal: Option<Isometry3<f64>>,
    /// The stimulator's next try.
    next_attempt: usize,
    /// The pulse input is high until this clock time.
    pulse_until: Option<f64>,
    /// The pulse on the input was given by hand.
    by_hand: bool,
    /// The gate output's level as last set.
    gate_level: bool,
    pulses: Vec<LoggedPulse>,
    withheld: usize,
    /// The dose each tick, with a coil model.
    dose: Option<mocomp_efield::DosePlans>,
}

impl Lockstep<'_, '_> {
    /// Before the coil robot's cycle, `tr` into the run: the plan's next target, and the
    /// stimulator (its pulse on the coil robot's input, two robot periods long).
    fn session_tick(&mut self, tr: f64) -> Result<(), ExperimentError> {
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
fn dose_target(plan: Option<&SessionPlan>, target: usize) -> Option<usize> {
    plan.filter(|p| !p.targets.is_empty()).map(|_| target)
}

/// What the drift monitor needs: the calibration, and the coil robot's recent joints (a marker
/// sample is compared with the robot where it was when the sample was acquired).
struct DriftWatch {
    base_from_tracker: Isometry3<f64>,
    flange_from_marker: Isometry3<f64>,
    q1: JointHistory,
}

impl crate::driver::Pace for Lockstep<'_, '_> {
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
        let w = &mut *self.world;
        if matches!(rec.mode, Mode::Faulted(_)) {
            w.robot1
                .keep_alive()
                .map_err(|e| io("commanding the coil robot", e))?;
        }
        let (sim1, inputs) = (&w.sim1, self.inputs);
        spin(Duration::from_secs(5), "a command to arrive", || {
            sim1.stats().inputs > inputs
        })?;
        w.advance()?;
        // The drift monitor: every coil-marker sample against the robot at its acquisition.
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
        let tr = self.t - self.t0;
        // The truth at the cycle's time (the joints before this tick's step): the true coil
        // against the selected target on the true head.
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
        // The session on this cycle: the gate (to the coil robot's output) and a pulse on its
        // input (the state after this tick's step carries it).
        let inputs = w.robot1.state().map(|s| s.digital_inputs);
        let step = self.session.cycle(&rec, inputs);
        if let Some(p) = step.pulse {
            let true_head = w.world_from_e2(&w.q_prev.1) * w.scene.e2_from_head;
            let dose_target = dose_target(self.plan, target);
            let dose_pct = self.dose.as_mut().map_or(f64::NAN, |d| {
                d.dose(dose_target, &(true_head.inverse() * true_coil)).pct
            });
            self.pulses.push(LoggedPulse {
                pulse: PulseAt {
                    t_s: p.t_s - self.t0,
                    ..p
                },
                truth: target_error,
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
            spin(Duration::from_secs(5), "the gate output to arrive", || {
                sim1.stats().inputs > n
            })?;
            self.gate_level = step.gate_open;
        }
        let e2 = w.world_from_e2(&w.q_now.1);
        let e1 = w.world_from_e1(&w.q_now.0);
        let actual = e2.inverse() * e1;
        // The coil's error in the loop's own frames, for its split into prediction and
        // execution ([`split_errors`]).
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
            target,
            target_error,
            measured_error: rec.coil_error,
            gate_open: step.gate_open,
            aimed_coil,
            goal_coil,
            model_coil,
            prediction_m: f64::NAN,
            execution_m: f64::NAN,
            standoff_m: rec.standoff_m + rec.filtered_m,
            dose_pct: {
                let dose_target = dose_target(self.plan, target);
                self.dose
                    .as_mut()
                    .map_or(f64::NAN, |d| d.dose(dose_target, &head_from_coil).pct)
            },
        });
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
}
