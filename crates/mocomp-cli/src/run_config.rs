//! The configuration file of `run`, `teach-goal` and `calibrate collect` (the schema, its
//! checks, and what follows from it: the loop's configuration, the simulated robot's start). One
//! module every command reads, so none of them imports another.

use crate::UsageError;
use anyhow::Context;
use mocomp_control::{CoilModel, HeadModel, LoopConfig, LoopParams, PredictorConfig};
use mocomp_geom::iso_from_ur_pose;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_kin::{Arm, Selection};
use mocomp_sim::{HeadMotion, TrackerModel};
use mocomp_ur::ServoParams;
use serde::Deserialize;

/// The configuration file. Units: metres, seconds, radians; poses are UR pose vectors
/// `[x, y, z, rx, ry, rz]` (metres, rotation vector in radians).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunFile {
    /// Stop after this many seconds (0: until Ctrl-C).
    #[serde(default)]
    pub duration_s: f64,
    /// Write every cycle to this CSV file.
    #[serde(default)]
    pub log_csv: Option<String>,
    /// The robot.
    pub robot: RobotSection,
    /// The tracker.
    pub tracker: TrackerSection,
    /// The frames.
    pub calibration: CalibrationSection,
    /// The goal.
    pub goal: GoalSection,
    /// The head's collision model.
    #[serde(default)]
    pub head: HeadSection,
    /// The coil's collision model.
    #[serde(default)]
    pub coil: CoilSection,
    /// servoj settings.
    #[serde(default)]
    pub servo: ServoSection,
    /// The head pose predictor.
    #[serde(default)]
    pub predictor: PredictorConfig,
    /// The loop's parameters.
    #[serde(default, rename = "loop")]
    pub params: LoopParams,
    /// `calibrate collect`.
    #[serde(default)]
    pub calibrate: CollectSection,
    /// Real-time scheduling of the loop and of the in-process simulators.
    #[serde(default)]
    pub realtime: mocomp_rt::RtConfig,
}

/// `[robot]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSection {
    /// ur3, ur5, ur10 (CB3), ur3e … ur30 (e-Series).
    pub model: mocomp_kin::Model,
    /// The controller's address.
    pub host: String,
    /// Start an in-process simulated controller on `host` (a loopback address).
    #[serde(default)]
    pub simulate: bool,
    /// The simulated robot's joints at start (default: the coil 15 cm out on the goal's axis).
    #[serde(default)]
    pub initial_joints_rad: Option<[f64; 6]>,
}

/// `[tracker]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrackerSection {
    /// Where the head's poses come from.
    pub source: TrackerSource,
    /// The OpenIGTLink server, host:port.
    #[serde(default)]
    pub igtl: Option<String>,
    /// The head marker's device name (TRANSFORM device or TDATA tool).
    #[serde(default = "default_device")]
    pub device: String,
    /// How the sender's timestamps map onto our clock: "estimated" (unsynchronised clocks: the
    /// offset is estimated from the smallest delay, which hides the sender's constant latency;
    /// give it as `fixed_latency_s`) or "synchronized" (same host, or PTP/NTP). The simulated
    /// tracker runs on this host and is always read as synchronized.
    #[serde(default)]
    pub timestamps: Timestamps,
    /// The sender's constant latency from acquisition to sending, s (with "estimated").
    #[serde(default)]
    pub fixed_latency_s: f64,
    /// The simulated tracker.
    #[serde(default)]
    pub simulated: SimTrackerSection,
}

/// `tracker.source`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrackerSource {
    /// An OpenIGTLink server at `tracker.igtl` (PLUS, 3D Slicer, a navigation system).
    Openigtlink,
    /// The simulated tracker, served over OpenIGTLink on loopback.
    Simulated,
}

impl std::fmt::Display for TrackerSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Openigtlink => "openigtlink",
            Self::Simulated => "simulated",
        })
    }
}

/// `tracker.timestamps`: how the sender's timestamps map onto our clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Timestamps {
    /// Unsynchronised clocks: the offset is estimated from the smallest delay (which hides the
    /// sender's constant latency: give it as `fixed_latency_s`).
    #[default]
    Estimated,
    /// The same host, or clocks synchronised by PTP/NTP.
    Synchronized,
}

fn default_device() -> String {
    "HeadToTracker".into()
}

/// `[tracker.simulated]`: the world the simulated tracker sees, its motion and its model.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimTrackerSection {
    /// The head at rest, base_from_head.
    pub base_from_head: [f64; 6],
    /// Where the tracker truly is, base_from_tracker (default: the configured calibration's, so
    /// the calibration is exact; set it to see a calibration error's effect).
    pub base_from_tracker: Option<[f64; 6]>,
    /// The calibration marker on the flange, flange_from_marker (for `calibrate collect`).
    pub flange_from_marker: [f64; 6],
    /// The head's motion.
    pub motion: HeadMotion,
    /// The tracker's model.
    pub model: TrackerModel,
}

impl Default for SimTrackerSection {
    fn default() -> Self {
        Self {
            base_from_head: [0.30, -0.12, -0.02, 0.0, 0.0, 0.3],
            base_from_tracker: None,
            flange_from_marker: [0.0, 0.06, 0.02, std::f64::consts::PI, 0.0, 0.0],
            motion: HeadMotion::Nods(mocomp_sim::motion::Nods::default()),
            model: TrackerModel::default(),
        }
    }
}

/// `[calibration]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationSection {
    /// A calibration result (`mocomp calibrate solve --out`): its Y is base_from_tracker.
    #[serde(default)]
    pub file: Option<String>,
    /// base_from_tracker, when no file is given.
    #[serde(default)]
    pub base_from_tracker: Option<[f64; 6]>,
    /// The coil's mounting, flange_from_coil.
    pub flange_from_coil: [f64; 6],
}

/// `[goal]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GoalSection {
    /// head_from_coil; +z of the coil points into the head.
    pub head_from_coil: [f64; 6],
}

/// `[head]`: an ellipsoid in the head marker's frame.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HeadSection {
    /// head_from_ellipsoid.
    pub head_from_ellipsoid: [f64; 6],
    /// Semi-axes, m.
    pub radii_m: [f64; 3],
}

impl Default for HeadSection {
    fn default() -> Self {
        Self {
            head_from_ellipsoid: [0.0; 6],
            radii_m: [0.075, 0.095, 0.11],
        }
    }
}

/// `[coil]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CoilSection {
    /// Radius seen from the head, m.
    pub radius_m: f64,
    /// Thickness behind the face, m.
    pub thickness_m: f64,
}

impl Default for CoilSection {
    fn default() -> Self {
        Self {
            radius_m: 0.04,
            thickness_m: 0.03,
        }
    }
}

/// `[servo]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ServoSection {
    /// servoj lookahead time, s (UR: 0.03–0.2).
    pub lookahead_s: f64,
    /// servoj gain (UR: 100–2000).
    pub gain: f64,
}

impl Default for ServoSection {
    fn default() -> Self {
        Self {
            lookahead_s: 0.03,
            gain: 1500.0,
        }
    }
}

pub(crate) fn pose(key: &str, v: &[f64; 6]) -> anyhow::Result<Isometry3<f64>> {
    iso_from_ur_pose(v).map_err(|e| UsageError(format!("{key}: {e}")).into())
}

fn positive(key: &str, v: f64) -> anyhow::Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(UsageError(format!("{key} = {v}: must be finite and > 0")).into())
    }
}

impl RunFile {
    /// Parses and checks a configuration; errors name the file and the key.
    pub fn parse(path: &str, text: &str) -> anyhow::Result<Self> {
        let one_line = |e: &dyn std::fmt::Display| e.to_string().trim_end().replace('\n', " ");
        let de = toml::Deserializer::parse(text)
            .map_err(|e| UsageError(format!("{path}: {}", one_line(&e))))?;
        // The key's whole path in the message (`tracker.timestamps`), not just its line.
        let mut f: Self = serde_path_to_error::deserialize(de)
            .map_err(|e| UsageError(format!("{path}: {}: {}", e.path(), one_line(e.inner()))))?;
        // A recorded motion's file is relative to this file's directory.
        let dir = std::path::Path::new(path)
            .parent()
            .unwrap_or(std::path::Path::new(""));
        f.tracker
            .simulated
            .motion
            .load_file(dir)
            .map_err(|e| UsageError(format!("{path}: tracker.simulated.motion.path: {e}")))?;
        let ctx = |e: anyhow::Error| match e.downcast::<UsageError>() {
            Ok(UsageError(m)) => anyhow::Error::from(UsageError(format!("{path}: {m}"))),
            Err(e) => e,
        };
        f.check().map_err(ctx)?;
        Ok(f)
    }

    fn check(&self) -> anyhow::Result<()> {
        self.calibrate.check()?;
        self.params
            .validate()
            .map_err(|e| UsageError(format!("loop.{e}")))?;
        self.predictor
            .validate()
            .map_err(|e| UsageError(format!("predictor.{e}")))?;
        self.realtime
            .validate()
            .map_err(|e| UsageError(e.to_string()))?;
        if self.tracker.source == TrackerSource::Openigtlink && self.tracker.igtl.is_none() {
            return Err(UsageError(
                "tracker.igtl: needed (host:port) for source \"openigtlink\"".into(),
            )
            .into());
        }
        if !(self.tracker.fixed_latency_s.is_finite()
            && (0.0..=1.0).contains(&self.tracker.fixed_latency_s))
        {
            return Err(UsageError(format!(
                "tracker.fixed_latency_s = {}: must be in [0, 1] s",
                self.tracker.fixed_latency_s
            ))
            .into());
        }
        let s = &self.tracker.simulated;
        s.motion
            .validate()
            .map_err(|e| UsageError(format!("tracker.simulated.motion.{e}")))?;
        s.model
            .validate()
            .map_err(|e| UsageError(format!("tracker.simulated.model.{e}")))?;
        if !(self.duration_s.is_finite() && self.duration_s >= 0.0) {
            return Err(UsageError(format!(
                "duration_s = {}: must be finite and ≥ 0",
                self.duration_s
            ))
            .into());
        }
        for (i, r) in self.head.radii_m.iter().enumerate() {
            positive(&format!("head.radii_m[{i}]"), *r)?;
        }
        positive("coil.radius_m", self.coil.radius_m)?;
        positive("coil.thickness_m", self.coil.thickness_m)?;
        if !(0.03..=0.2).contains(&self.servo.lookahead_s) {
            return Err(UsageError(format!(
                "servo.lookahead_s = {}: must be in [0.03, 0.2]",
                self.servo.lookahead_s
            ))
            .into());
        }
        if !(100.0..=2000.0).contains(&self.servo.gain) {
            return Err(UsageError(format!(
                "servo.gain = {}: must be in [100, 2000]",
                self.servo.gain
            ))
            .into());
        }
        if self.calibration.file.is_none() && self.calibration.base_from_tracker.is_none() {
            return Err(UsageError(
                "calibration: give `file` (a calibration result) or `base_from_tracker`".into(),
            )
            .into());
        }
        pose(
            "calibration.flange_from_coil",
            &self.calibration.flange_from_coil,
        )?;
        pose("goal.head_from_coil", &self.goal.head_from_coil)?;
        pose("head.head_from_ellipsoid", &self.head.head_from_ellipsoid)?;
        pose("tracker.simulated.base_from_head", &s.base_from_head)?;
        pose(
            "tracker.simulated.flange_from_marker",
            &s.flange_from_marker,
        )?;
        if let Some(y) = &s.base_from_tracker {
            pose("tracker.simulated.base_from_tracker", y)?;
        }
        if let Some(y) = &self.calibration.base_from_tracker {
            pose("calibration.base_from_tracker", y)?;
        }
        Ok(())
    }

    /// base_from_tracker, from the calibration file (relative to `dir`) or the inline pose.
    pub(crate) fn base_from_tracker(
        &self,
        dir: &std::path::Path,
    ) -> anyhow::Result<Isometry3<f64>> {
        if let Some(file) = &self.calibration.file {
            let path = dir.join(file);
            let text = std::fs::read_to_string(&path)
                .with_context(|| format!("calibration.file {}", path.display()))?;
            let c = mocomp_calib::CalibrationFile::from_toml_str(&text)
                .with_context(|| format!("calibration.file {}", path.display()))?;
            Ok(c.transforms()?.1)
        } else if let Some(y) = &self.calibration.base_from_tracker {
            pose("calibration.base_from_tracker", y)
        } else {
            Err(UsageError("calibration: no base_from_tracker".into()).into())
        }
    }

    pub(crate) fn loop_config(&self, y: Isometry3<f64>, period: f64) -> anyhow::Result<LoopConfig> {
        let mut cfg = LoopConfig::new(
            y,
            pose(
                "calibration.flange_from_coil",
                &self.calibration.flange_from_coil,
            )?,
            pose("goal.head_from_coil", &self.goal.head_from_coil)?,
            period,
        );
        cfg.servo = ServoParams {
            time_s: period,
            lookahead_s: self.servo.lookahead_s,
            gain: self.servo.gain,
        };
        cfg.predictor = self.predictor;
        cfg.head = HeadModel {
            head_from_ellipsoid: pose("head.head_from_ellipsoid", &self.head.head_from_ellipsoid)?,
            radii: Vector3::from(self.head.radii_m),
        };
        cfg.coil = CoilModel {
            radius: self.coil.radius_m,
            thickness: self.coil.thickness_m,
        };
        cfg.params = self.params;
        Ok(cfg)
    }
}

/// `[calibrate]`: how `calibrate collect` runs. Units: metres, radians, seconds.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CollectSection {
    /// The flange marker's device name (TRANSFORM device or TDATA tool).
    pub device: String,
    /// Number of poses.
    pub poses: usize,
    /// Smallest rotation from the centre pose, rad.
    pub min_rotation_rad: f64,
    /// Largest rotation from the centre pose, rad.
    pub max_rotation_rad: f64,
    /// Shift of the flange per axis, up to ±this, m.
    pub spread_m: f64,
    /// The centre flange pose, base_from_flange (default: where the robot is).
    pub center: Option<[f64; 6]>,
    /// A rough flange_from_marker: the poses turn about the marker's centre (default: 5 cm off
    /// the flange's axis, facing back along it).
    pub flange_from_marker_guess: [f64; 6],
    /// Keep the marker in the tracker's view, judged with the configured base_from_tracker.
    pub check_view: bool,
    /// Tracker samples averaged at each pose.
    pub samples_per_pose: usize,
    /// Wait this long after each move before measuring, s.
    pub settle_s: f64,
    /// Joint speed of the moves, rad/s.
    pub joint_speed_rad_s: f64,
    /// Joint acceleration of the moves, rad/s².
    pub joint_accel_rad_s2: f64,
    /// Give up on a move after this long, s.
    pub move_timeout_s: f64,
    /// Solver: li, shah or refined.
    pub method: mocomp_calib::Method,
    /// Expected tracker noise per axis (1σ), m.
    pub tracker_noise_m: f64,
    /// Expected tracker rotation noise per axis (1σ), rad.
    pub tracker_noise_rad: f64,
    /// Expected robot noise per axis (1σ), m.
    pub robot_noise_m: f64,
    /// Expected robot rotation noise per axis (1σ), rad.
    pub robot_noise_rad: f64,
    /// Where to save the calibration (relative to the configuration file's directory).
    pub out: String,
    /// Where to save the measured pairs (relative to the configuration file's directory).
    pub pairs_csv: Option<String>,
}

impl Default for CollectSection {
    fn default() -> Self {
        Self {
            device: "MarkerToTracker".into(),
            poses: 15,
            min_rotation_rad: 15f64.to_radians(),
            max_rotation_rad: 35f64.to_radians(),
            spread_m: 0.06,
            center: None,
            flange_from_marker_guess: [0.0, 0.05, 0.0, std::f64::consts::PI, 0.0, 0.0],
            check_view: true,
            samples_per_pose: 10,
            settle_s: 0.3,
            joint_speed_rad_s: 0.8,
            joint_accel_rad_s2: 1.5,
            move_timeout_s: 20.0,
            method: mocomp_calib::Method::Refined,
            tracker_noise_m: 1e-4,
            tracker_noise_rad: 1e-3,
            robot_noise_m: 3e-5,
            robot_noise_rad: 2e-4,
            out: "calibration.toml".into(),
            pairs_csv: Some("calibration-pairs.csv".into()),
        }
    }
}

impl CollectSection {
    /// Checks every value; errors name the key.
    pub fn check(&self) -> Result<(), UsageError> {
        let bad = |k: &str, v: f64, what: &str| UsageError(format!("calibrate.{k} = {v}: {what}"));
        if self.poses < 3 {
            return Err(bad("poses", self.poses as f64, "must be at least 3"));
        }
        if self.samples_per_pose == 0 {
            return Err(bad("samples_per_pose", 0.0, "must be at least 1"));
        }
        for (k, v) in [
            ("min_rotation_rad", self.min_rotation_rad),
            ("spread_m", self.spread_m),
            ("settle_s", self.settle_s),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(k, v, "must be finite and ≥ 0"));
            }
        }
        // Zero noise would weight the solver's residuals infinitely.
        for (k, v) in [
            ("tracker_noise_m", self.tracker_noise_m),
            ("tracker_noise_rad", self.tracker_noise_rad),
            ("robot_noise_m", self.robot_noise_m),
            ("robot_noise_rad", self.robot_noise_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(k, v, "must be finite and > 0"));
            }
        }
        if !(self.max_rotation_rad.is_finite()
            && self.max_rotation_rad > self.min_rotation_rad
            && self.max_rotation_rad <= std::f64::consts::PI)
        {
            return Err(bad(
                "max_rotation_rad",
                self.max_rotation_rad,
                "must be above min_rotation_rad and at most π",
            ));
        }
        for (k, v, hi) in [
            ("joint_speed_rad_s", self.joint_speed_rad_s, 3.0),
            ("joint_accel_rad_s2", self.joint_accel_rad_s2, 40.0),
            ("move_timeout_s", self.move_timeout_s, 600.0),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= hi) {
                return Err(bad(k, v, &format!("must be in (0, {hi}]")));
            }
        }
        Ok(())
    }
}

pub(crate) fn initial_joints(
    file: &RunFile,
    arm: &Arm,
    cfg: &LoopConfig,
) -> anyhow::Result<[f64; 6]> {
    if let Some(q) = file.robot.initial_joints_rad {
        return Ok(q);
    }
    // The coil 15 cm out on the goal's axis, for the head at rest.
    let rest = pose(
        "tracker.simulated.base_from_head",
        &file.tracker.simulated.base_from_head,
    )?;
    let out = rest
        * cfg.head_from_coil_goal
        * Isometry3::translation(0.0, 0.0, -0.15)
        * cfg.flange_from_coil.inverse();
    let seeds = [
        [0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
        [0.0, -1.57, 1.57, -1.57, -1.57, 0.0],
        [1.57, -1.3, 1.6, -1.87, -1.57, 0.0],
    ];
    for seed in seeds {
        if let Ok(c) = arm.ik_closest(&out, &seed, &Selection::tracking(0.1)) {
            return Ok(c.joints);
        }
    }
    Err(UsageError(
        "robot.initial_joints_rad: needed, the default start (15 cm out on the goal's axis) is \
         out of reach"
            .into(),
    )
    .into())
}
