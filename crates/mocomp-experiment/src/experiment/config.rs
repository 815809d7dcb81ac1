//! The experiment's settings and their check, and the paper's goal.

use super::*;
use crate::session_plan::SessionPlan;
use mocomp_control::baseline::PaperController;
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Vector3};
use mocomp_kin::Model;
use mocomp_sim::HeadMotion;
use mocomp_sim::TrackerModel;
use mocomp_sim::contact::ContactParams;
use std::net::IpAddr;

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
