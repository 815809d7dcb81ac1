//! The one configuration of every command that takes `--config` (`run`, `demo`, `calibrate
//! collect`, `teach-goal`). Units: metres, seconds, radians; poses are UR pose vectors
//! `[x, y, z, rx, ry, rz]` (metres, rotation vector in radians).
//!
//! Every key has its default here, once (the `Default` impls below, and the components' own for
//! `[predictor]`, `[loop]`, `[realtime]`, the motion and the tracker model); `mocomp config
//! print` prints them through the `config_file` module, whose commented template a test holds to
//! these values. A file with no keys at all describes the built-in simulated world: a simulated
//! UR3 and tracker on loopback. What a real robot or tracker needs (its calibration, the coil's
//! mounting, the goal) has no default there: [`Setup::load`] names the key that is missing.
//!
//! Unknown keys and bad values are refused naming the key's path (and, where the TOML itself is
//! at fault, its line). Choices are enums; poses are [`Pose`]; ranges go through [`Check`].

pub use crate::coil_config::CoilSection;
pub use crate::config_check::Check;
use crate::{AppError, Context};
use mocomp_control::baseline::PaperController;
use mocomp_control::{CoilModel, HeadModel, LoopConfig, LoopParams, PredictorConfig};
use mocomp_geom::iso_from_ur_pose;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_kin::{Arm, Model, Selection};
use mocomp_sim::{HeadMotion, TrackerModel};
use mocomp_ur::ServoParams;
use serde::{Deserialize, Serialize};
use std::net::IpAddr;
use std::path::{Path, PathBuf};

/// A pose as a UR pose vector `[x, y, z, rx, ry, rz]` (metres, rotation vector in radians),
/// checked when read. It keeps the six numbers as written, so a printed file reads them back
/// exactly.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "[f64; 6]", into = "[f64; 6]")]
pub struct Pose {
    raw: [f64; 6],
    iso: Isometry3<f64>,
}

impl Pose {
    /// The rigid transform.
    pub fn iso(&self) -> Isometry3<f64> {
        self.iso
    }

    /// The six numbers.
    pub fn raw(&self) -> [f64; 6] {
        self.raw
    }
}

impl TryFrom<[f64; 6]> for Pose {
    type Error = mocomp_geom::GeomError;
    fn try_from(raw: [f64; 6]) -> Result<Self, Self::Error> {
        Ok(Self {
            raw,
            iso: iso_from_ur_pose(&raw)?,
        })
    }
}

impl From<Pose> for [f64; 6] {
    fn from(p: Pose) -> Self {
        p.raw
    }
}

/// A pose from constant numbers (the defaults below): finite numbers always convert.
fn pose_const(raw: [f64; 6]) -> Pose {
    Pose {
        raw,
        iso: iso_from_ur_pose(&raw).unwrap_or_else(|_| Isometry3::identity()),
    }
}

/// The configuration. Scalars first: TOML puts tables after them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// `mocomp run`: stop after this many seconds (0: until Ctrl-C).
    pub duration_s: f64,
    /// `mocomp run`: write every cycle to this CSV file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub log_csv: Option<String>,
    /// `mocomp run` and `mocomp demo`: record the session to this MCAP file (ROS 2 profile: the ROS 2 node's
    /// topics and every cycle record), whether or not `[ros2]` is on.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub record_mcap: Option<String>,
    /// The robot.
    pub robot: RobotSection,
    /// The tracker.
    pub tracker: TrackerSection,
    /// The frames.
    pub calibration: CalibrationSection,
    /// The goal.
    pub goal: GoalSection,
    /// The head's collision model.
    pub head: HeadSection,
    /// `mocomp register`: patient-to-image registration.
    pub registration: crate::registration_config::RegistrationSection,
    /// The coil's collision model.
    pub coil: CoilSection,
    /// servoj settings.
    pub servo: ServoSection,
    /// The head pose predictor.
    pub predictor: PredictorConfig,
    /// The loop's parameters.
    #[serde(rename = "loop")]
    pub params: LoopParams,
    /// `calibrate collect` (and the experiment's calibrations).
    pub calibrate: CollectSection,
    /// Real-time scheduling of the loop and of the in-process simulators.
    pub realtime: mocomp_rt::RtConfig,
    /// `mocomp demo`: the paper's two-robot experiment.
    pub experiment: ExperimentSection,
    /// `mocomp run`: the clinical session around the loop.
    pub session: SessionSection,
    /// `mocomp run`: mocomp as a ROS 2 node.
    pub ros2: Ros2Section,
}

/// `[ros2]`: `mocomp run` as a ROS 2 node (no ROS installation needed): it publishes
/// `/joint_states`, `/tf`, `/mocomp/coil_pose`, `/mocomp/head_pose` and `/diagnostics`, and serves
/// `/mocomp/hold` and `/mocomp/resume` (`std_srvs/Trigger`). `tracker.source = "ros2"` takes the
/// head's poses from a `geometry_msgs/PoseStamped` topic with or without it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Section {
    /// Publish and serve (or: `mocomp run --ros2`).
    pub enabled: bool,
    /// The DDS domain (default: `ROS_DOMAIN_ID`, else 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub domain_id: Option<u16>,
    /// The node's name.
    pub node_name: String,
    /// Joint states, TF and poses at most this often, Hz (0: every cycle, the robot's rate).
    pub publish_hz: f64,
    /// The head's poses for `tracker.source = "ros2"`: a `geometry_msgs/PoseStamped` topic, the
    /// head marker in the tracker's frame, stamped at acquisition.
    pub head_topic: String,
    /// How services map onto DDS: "enhanced" (Fast DDS, ROS 2's default) or "cyclone"
    /// (`rmw_cyclonedds_cpp`), as the other nodes' DDS.
    pub service_mapping: mocomp_ros2::node::ServiceMappingName,
    /// The frame names.
    pub frames: mocomp_ros2::Frames,
}

impl Default for Ros2Section {
    fn default() -> Self {
        Self {
            enabled: false,
            domain_id: None,
            node_name: "mocomp".into(),
            publish_hz: 0.0,
            head_topic: "/mocomp/tracker/head".into(),
            service_mapping: mocomp_ros2::node::ServiceMappingName::Enhanced,
            frames: mocomp_ros2::Frames::default(),
        }
    }
}

impl Ros2Section {
    /// The node's settings: the domain from the section, else `ROS_DOMAIN_ID` (which must then
    /// be a number below 233, DDS's range for it), else 0.
    pub fn node_config(&self, head: bool) -> Result<mocomp_ros2::Ros2Config, AppError> {
        let domain_id = match (self.domain_id, std::env::var("ROS_DOMAIN_ID")) {
            (Some(d), _) => d,
            (None, Ok(v)) if !v.trim().is_empty() => v
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or_else(|| {
                    AppError::Config(format!("ROS_DOMAIN_ID={v:?}: must be a number 0 to 232"))
                })?,
            _ => 0,
        };
        Ok(mocomp_ros2::Ros2Config {
            domain_id,
            node_name: self.node_name.clone(),
            frames: self.frames.clone(),
            head_topic: head.then(|| self.head_topic.clone()),
            service_mapping: self.service_mapping,
            ..mocomp_ros2::Ros2Config::default()
        })
    }
}

/// `[session]`: the clinical session around `mocomp run`'s loop: the targets, the on-target gate
/// on a robot output, the stimulator's pulses and their log, the calibration's drift monitor.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SessionSection {
    /// The session's targets file (`mocomp targets`, `teach-goal --name`), relative to this
    /// file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub targets: Option<String>,
    /// The target the loop starts on (a name in `targets`; default: `[goal]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// Write one CSV row per pulse to this file (relative to this file): its UTC time, the
    /// target, the coil's errors, its pose on the image and distance to the scalp, the output.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pulse_log: Option<String>,
    /// The stimulator's output, % of its maximum, recorded with each pulse whose stimulator does
    /// not say it (a pulse on a robot input says nothing; a STRING `pulse output=65` does).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stimulator_output_pct: Option<f64>,
    /// The robot's digital output that carries the gate (0-7 standard, 8-15 configurable).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gate_output: Option<u32>,
    /// The robot's digital input the stimulator's pulse comes in on (0-17).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pulse_input: Option<u32>,
    /// Publish the gate to the tracker's OpenIGTLink server as STRING messages of this device
    /// (`open`, or `shut: why`), and, without a `pulse_input`, take a STRING `pulse` from it as
    /// a pulse (one source of pulses, never two: each would log the same pulse).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub igtl_device: Option<String>,
    /// The tracker device of a marker on the flange, for the drift monitor (the calibration
    /// marker's `calibrate.device`; none: no drift monitor).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub marker_device: Option<String>,
    /// That marker on the flange, flange_from_marker (default: the calibration file's X; with
    /// the simulated tracker, `tracker.simulated.flange_from_marker`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flange_from_marker: Option<Pose>,
    /// The on-target gate's tolerances and dwell.
    pub gate: mocomp_session::GateParams,
    /// The drift monitor's levels.
    pub drift: mocomp_session::DriftParams,
    /// The simulated world's stimulator (with `robot.simulate`): pulses at `rate_hz` while the
    /// gate output is high.
    pub simulated_stimulator: SimStimulatorSection,
}

/// `[session.simulated_stimulator]`: a stimulator in the simulated world, its trigger wired
/// through the gate output: while the output is high it fires at `rate_hz`, each pulse reported
/// as the session is configured to take it (the robot's input, and an OpenIGTLink STRING).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimStimulatorSection {
    /// Pulses per second while the gate is open (0: no stimulator).
    pub rate_hz: f64,
    /// The output it announces with each pulse over OpenIGTLink (`pulse output=…`, stamped
    /// with its own clock), %; none: a plain `pulse`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output_pct: Option<f64>,
}

impl SessionSection {
    /// The session's parameters.
    pub fn params(&self) -> mocomp_session::SessionParams {
        mocomp_session::SessionParams {
            gate: self.gate,
            drift: self.drift,
            gate_output: self.gate_output,
            pulse_input: self.pulse_input,
        }
    }
}

/// `[robot]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotSection {
    /// ur3, ur5, ur10 (CB3), ur3e … ur30 (e-Series).
    pub model: Model,
    /// The controller's address.
    pub host: String,
    /// Start an in-process simulated controller on `host` (a loopback address).
    pub simulate: bool,
    /// The simulated robot's joints at start (default: the coil 15 cm out on the goal's axis).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub initial_joints_rad: Option<[f64; 6]>,
    /// Zero the force/torque sensor (`zero_ftsensor()`) before the loop starts: e-Series only,
    /// and nothing may touch the coil then (a contact present would read as zero afterwards).
    pub zero_force_sensor: bool,
}

impl Default for RobotSection {
    /// A simulated UR3 (the paper's) on 127.0.0.2.
    fn default() -> Self {
        Self {
            model: Model::Ur3,
            host: "127.0.0.2".into(),
            simulate: true,
            initial_joints_rad: None,
            zero_force_sensor: false,
        }
    }
}

/// `[tracker]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerSection {
    /// Where the head's poses come from.
    pub source: TrackerSource,
    /// The OpenIGTLink server, host:port.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub igtl: Option<String>,
    /// The head marker's device name (TRANSFORM device or TDATA tool).
    pub device: String,
    /// How the sender's timestamps map onto our clock ("auto": the simulated tracker and
    /// camera, on this host, as synchronized; any other as estimated).
    pub timestamps: Timestamps,
    /// The sender's constant latency from acquisition to sending, s (with "estimated").
    pub fixed_latency_s: f64,
    /// The simulated tracker (and the simulated world the camera sees).
    pub simulated: SimTrackerSection,
    /// The simulated depth camera (source "camera").
    pub camera: CameraSection,
    /// An Azure Kinect, live or a recording (source "k4a").
    pub k4a: K4aSection,
}

impl Default for TrackerSection {
    fn default() -> Self {
        Self {
            source: TrackerSource::Simulated,
            igtl: None,
            device: "HeadToTracker".into(),
            timestamps: Timestamps::Auto,
            fixed_latency_s: 0.0,
            simulated: SimTrackerSection::default(),
            camera: CameraSection::default(),
            k4a: K4aSection::default(),
        }
    }
}

/// `tracker.source`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrackerSource {
    /// An OpenIGTLink server at `tracker.igtl` (PLUS, 3D Slicer, a navigation system).
    Openigtlink,
    /// The simulated tracker, served over OpenIGTLink on loopback.
    Simulated,
    /// A simulated depth camera (IR + depth frames) tracked by the paper's pipeline
    /// (`[tracker.camera]`), its poses served over OpenIGTLink on loopback.
    Camera,
    /// A ROS 2 `geometry_msgs/PoseStamped` topic (`ros2.head_topic`): `mocomp run` only.
    Ros2,
    /// An Azure Kinect (a device, or a recording played back) tracked by the paper's pipeline
    /// (`[tracker.k4a]`), its poses served over OpenIGTLink on loopback.
    K4a,
}

impl TrackerSource {
    /// Whether the head and its tracker are simulated (the simulated tracker or camera), so the
    /// frames and the goal have defaults.
    pub fn simulated(self) -> bool {
        matches!(self, Self::Simulated | Self::Camera)
    }
}

impl std::fmt::Display for TrackerSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Openigtlink => "openigtlink",
            Self::Simulated => "simulated",
            Self::Camera => "camera",
            Self::Ros2 => "ros2",
            Self::K4a => "k4a",
        })
    }
}

/// `tracker.timestamps`: how the sender's timestamps map onto our clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Timestamps {
    /// Synchronized for the simulated tracker or camera (this host's clock), estimated for any
    /// other sender.
    Auto,
    /// Unsynchronised clocks: the offset is estimated from the smallest delay (which hides the
    /// sender's constant latency: give it as `fixed_latency_s`).
    Estimated,
    /// The same host, or clocks synchronised by PTP/NTP.
    Synchronized,
}

/// `[tracker.simulated]`: the world the simulated tracker sees, its motion and its model.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimTrackerSection {
    /// The head at rest, base_from_head.
    pub base_from_head: Pose,
    /// Where the tracker truly is, base_from_tracker (default: the configured calibration's, so
    /// the calibration is exact; set it to see a calibration error's effect).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_from_tracker: Option<Pose>,
    /// The calibration marker on the flange, flange_from_marker (for `calibrate collect`).
    pub flange_from_marker: Pose,
    /// The head's motion.
    pub motion: HeadMotion,
    /// The tracker's model.
    pub model: TrackerModel,
    /// Where its OpenIGTLink server listens, host:port (port 0: any free one). The loop
    /// connects there, or to `tracker.igtl` when that is given (the same server seen through a
    /// relay or another host's address).
    pub serve: String,
    /// `mocomp register --simulate`: where the image truly lies on the head marker,
    /// head_from_image (default: `[head] head_from_image`, the registered one when `[head]
    /// registration` is set, as the simulated world takes it for the head).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head_from_image: Option<Pose>,
    /// `mocomp register --simulate`: the operator with the pointer, and the patient's skin.
    pub operator: mocomp_sim::operator::OperatorConfig,
}

impl Default for SimTrackerSection {
    /// The head in front of the robot, the marker on the flange facing back, smooth random
    /// motion (up to 20 mm/s and 10°/s, as the paper's experiment).
    fn default() -> Self {
        Self {
            base_from_head: pose_const([0.30, -0.12, -0.02, 0.0, 0.0, 0.3]),
            base_from_tracker: None,
            flange_from_marker: pose_const([0.0, 0.06, 0.02, std::f64::consts::PI, 0.0, 0.0]),
            motion: HeadMotion::Random(mocomp_sim::motion::RandomMotion::default()),
            model: TrackerModel::default(),
            serve: "127.0.0.1:0".into(),
            head_from_image: None,
            operator: mocomp_sim::operator::OperatorConfig::default(),
        }
    }
}

/// `[tracker.camera]`: a simulated depth camera (a Kinect v2's intrinsics: 512×424 IR and depth)
/// at the tracker's place, seeing the head marker's fiducials in the simulated world of
/// `[tracker.simulated]` (rest pose, motion). Each frame is rendered (the fiducials as bright
/// discs with depth holes, IR and depth noise) and tracked by the paper's pipeline with
/// `params`; the poses go out over OpenIGTLink on loopback, as from a tracking server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraSection {
    /// Frames per second.
    pub rate_hz: f64,
    /// Seeds the frames' noise (and where the distractors are).
    pub seed: u64,
    /// Large saturated patches in view (sunlight), which the pipeline must reject as too large.
    pub sun_spots: usize,
    /// Fiducial-sized bright spots in view (reflections), which it must leave unmatched.
    pub reflections: usize,
    /// The head marker's fiducials (.toml with points_mm, Atracsys .ini, NDI .rom; relative to
    /// the configuration file); default: the NDI 8700449 geometry.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geometry: Option<String>,
    /// The pipeline's steps 2–7 (as `mocomp track --params`); changeable while the loop runs.
    pub params: mocomp_vision::TrackParams,
}

impl Default for CameraSection {
    /// A Kinect v2's 30 frames a second, the pipeline's defaults.
    fn default() -> Self {
        Self {
            rate_hz: 30.0,
            seed: 1,
            sun_spots: 0,
            reflections: 0,
            geometry: None,
            params: mocomp_vision::TrackParams::default(),
        }
    }
}

/// How a recording is played for `tracker.source = "k4a"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PlaybackPace {
    /// Each capture when its timestamp comes, as the camera delivered it.
    #[default]
    RealTime,
    /// As fast as the SDK reads and the pipeline tracks.
    Fast,
}

/// `[tracker.k4a]`: an Azure Kinect DK (or an Orbbec Femto through Orbbec's k4a-compatible
/// library) tracked by the paper's pipeline, through the Azure Kinect SDK loaded at run time:
/// a device (by serial) or a recording (`.mkv`). Each frame is stamped with its exposure on
/// this host's clock (the device's timestamps mapped by the fastest arrivals, less
/// `least_delay_s`); dropped frames, an unplugged device and a recording's end are named in the
/// run's notes, and the loop holds on the stale tracker that follows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct K4aSection {
    /// The SDK's directory (libk4a, libk4arecord 1.4; e.g. pyk4a-bundle's `pyk4a_bundle.libs`);
    /// default: `MOCOMP_K4A_SDK_DIR`, else the system's library path.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sdk_dir: Option<String>,
    /// The device's serial number (default: the only one connected).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub serial: Option<String>,
    /// Play this recording instead of a device (relative to the configuration file).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub recording: Option<String>,
    /// How a recording is played: "real_time" or "fast".
    pub playback: PlaybackPace,
    /// The device's depth mode.
    pub depth_mode: mocomp_k4a::DepthMode,
    /// The device's frames per second: 5, 15 or 30.
    pub fps: u32,
    /// From the middle of a frame's exposure to the fastest the host receives it, s (the part of
    /// the latency a host cannot see; the camera's datasheet or a flash test gives it).
    pub least_delay_s: f64,
    /// The head marker's fiducials (.toml with points_mm, Atracsys .ini, NDI .rom; relative to
    /// the configuration file); default: the NDI 8700449 geometry.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub geometry: Option<String>,
    /// The pipeline's steps 2–7 (as `mocomp track --params`); changeable while the loop runs.
    pub params: mocomp_vision::TrackParams,
}

impl Default for K4aSection {
    /// NFOV unbinned at 30 frames a second.
    fn default() -> Self {
        Self {
            sdk_dir: None,
            serial: None,
            recording: None,
            playback: PlaybackPace::RealTime,
            depth_mode: mocomp_k4a::DepthMode::NfovUnbinned,
            fps: 30,
            least_delay_s: 0.0,
            geometry: None,
            params: mocomp_vision::TrackParams::default(),
        }
    }
}

/// `[calibration]`: the frames the loop computes with.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationSection {
    /// A calibration result (`mocomp calibrate solve --out`): its Y is base_from_tracker.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub file: Option<String>,
    /// base_from_tracker, when no file is given (default with the simulated tracker:
    /// [`SIM_BASE_FROM_TRACKER`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_from_tracker: Option<Pose>,
    /// The coil's mounting, flange_from_coil (default on a simulated robot:
    /// [`SIM_FLANGE_FROM_COIL`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flange_from_coil: Option<Pose>,
}

/// `[goal]`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GoalSection {
    /// head_from_coil; +z of the coil points into the head (default with the simulated tracker:
    /// [`SIM_HEAD_FROM_COIL`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head_from_coil: Option<Pose>,
}

/// The simulated tracker's place, 1.1 m up and out, looking at the head: base_from_tracker.
pub const SIM_BASE_FROM_TRACKER: [f64; 6] = [1.0, 0.1, 0.9, 2.0019, -1.4693, -0.5718];
/// The simulated robot's coil mounting, 5 cm out on the flange axis: flange_from_coil.
pub const SIM_FLANGE_FROM_COIL: [f64; 6] = [0.0, 0.0, 0.05, 0.0, 0.0, 0.0];
/// The simulated head's goal: on top, 3 mm off the scalp, +z into the head: head_from_coil.
pub const SIM_HEAD_FROM_COIL: [f64; 6] = [0.0, 0.0, 0.113, std::f64::consts::PI, 0.0, 0.0];

/// `[head]`: the patient's scalp from a scan (`mesh`), or else an ellipsoid, in the head
/// marker's frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HeadSection {
    /// Where the ellipsoid lies in the image's frame (without a mesh; the image's frame is the
    /// head marker's until `head_from_image` says otherwise).
    pub head_from_ellipsoid: Pose,
    /// Semi-axes, m (without a mesh).
    pub radii_m: [f64; 3],
    /// The scalp's surface file (STL, OBJ, PLY, GIfTI, FreeSurfer), or a T1 MRI in NIfTI
    /// (`.nii`, `.nii.gz`) whose scalp is segmented (relative to the configuration's
    /// directory): the head model instead of the ellipsoid.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh: Option<PathBuf>,
    /// The unit of a mesh format that carries none (STL, OBJ, PLY), or of a NIfTI whose header
    /// states none: "mm" or "m".
    #[serde(skip_serializing_if = "Option::is_none")]
    pub units: Option<String>,
    /// A NIfTI's intensity at and above which a voxel is head (without it: Otsu's threshold).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
    /// The most triangles a scalp segmented from a NIfTI may have.
    pub max_triangles: usize,
    /// head_from_image: the image's frame (a mesh file's, an MRI's RAS; the ellipsoid's and the
    /// landmarks') in the head marker's frame, until registration measures it.
    pub head_from_image: Pose,
    /// Landmarks in the image (RAS, **millimetres**), by name: `nasion`, `inion`, `lpa`, `rpa`
    /// (the 10-20 system is measured from these four; registration pairs any it shares with
    /// the touched ones), e.g. `nasion = [1.5, 85.1, -34.8]`.
    #[serde(skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub landmarks: std::collections::BTreeMap<String, [f64; 3]>,
    /// Landmarks from a file (relative to the configuration's directory): 3D Slicer markups
    /// (`.mrk.json`, LPS or RAS) or a SimNIBS positions CSV (its `Fiducial` rows); a landmark
    /// also in `[head.landmarks]` is taken from there.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub landmarks_file: Option<PathBuf>,
    /// The registration `mocomp register` wrote (relative to the configuration's directory):
    /// its head_from_image replaces the one above.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub registration: Option<PathBuf>,
    /// The largest estimated target registration error at the goal compensation starts with,
    /// mm; above it `mocomp run` refuses unless the operator overrides it (logged in the
    /// registration file).
    pub max_tre_mm: f64,
    /// The registration as read, and the file's absolute path; not part of the file.
    #[serde(skip)]
    pub registered: Option<(PathBuf, crate::registration_file::Record)>,
    /// The mesh as read, mended and built ([`Config::load_head`]); not part of the file.
    #[serde(skip)]
    pub loaded: Option<HeadModel>,
    /// Where the loaded mesh's scalp came from (a T1's segmented now or kept from before);
    /// not part of the file.
    #[serde(skip)]
    pub scalp_from: Option<crate::head_file::ScalpFrom>,
}

impl Default for HeadSection {
    fn default() -> Self {
        Self {
            head_from_ellipsoid: pose_const([0.0; 6]),
            radii_m: [0.075, 0.095, 0.11],
            mesh: None,
            units: None,
            threshold: None,
            max_triangles: mocomp_mri::DEFAULT_MAX_TRIANGLES,
            head_from_image: pose_const([0.0; 6]),
            landmarks: std::collections::BTreeMap::new(),
            landmarks_file: None,
            registration: None,
            max_tre_mm: 3.0,
            registered: None,
            loaded: None,
            scalp_from: None,
        }
    }
}

/// `[servo]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
            gain: 2000.0,
        }
    }
}

/// `[calibrate]`: how `calibrate collect` runs (the experiment takes `poses` and
/// `samples_per_pose`). Units: metres, radians, seconds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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
    #[serde(skip_serializing_if = "Option::is_none")]
    pub center: Option<Pose>,
    /// A rough flange_from_marker: the poses turn about the marker's centre.
    pub flange_from_marker_guess: Pose,
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
    /// Where to save the measured pairs (beside the calibration).
    #[serde(skip_serializing_if = "Option::is_none")]
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
            flange_from_marker_guess: pose_const([0.0, 0.05, 0.0, std::f64::consts::PI, 0.0, 0.0]),
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

/// `[experiment]`: `mocomp demo`, the paper's two-robot experiment. The coil robot U1 is
/// `[robot]` (model, and host as its simulator's loopback address); the head moves as
/// `[tracker.simulated.motion]`, seen by `[tracker.simulated.model]`; both robots calibrate with
/// `calibrate.poses` and `calibrate.samples_per_pose`; the `mocomp` controller runs with
/// `[predictor]`, `[loop]`, `[head]`, `[coil]` and `[servo]`. The experiment builds its own
/// scene, calibrates itself and has its own goal, so `[calibration]`, `[goal]`, the simulated
/// tracker's placement and `[realtime]` are not used by it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExperimentSection {
    /// Compensation time per controller, s.
    pub duration_s: f64,
    /// Seeds the random motion and the tracker's noise (overrides their own `seed` keys).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// U2, which carries the head phantom (default: a UR5 of U1's series: ur5 or ur5e).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head_robot: Option<Model>,
    /// U2's simulator's address (loopback).
    pub head_host: IpAddr,
    /// The goal between the end-effectors `E2_T_E1,g`, rows of a 4×4 matrix with translation in
    /// mm (the paper's).
    pub goal_e2_from_e1_mm: [[f64; 4]; 4],
    /// The `paper` controller.
    pub paper: PaperController,
    /// On the scalp: both controllers' goal is moved along the coil's axis until it touches;
    /// `mocomp` holds `loop.contact_force_n` there by its admittance (`force_sensing` and
    /// `contact_mode` on), the `paper` controller holds the pose.
    pub contact: bool,
    /// Where on the head the goal puts the coil: over the scalp point nearest this point (head
    /// marker's frame, mm), 3 mm off, its axis along the scalp's normal there (the phantom is
    /// mounted on the head robot so that the paper's goal does it). [on top of the head]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goal_near_mm: Option<[f64; 3]>,
    /// The head model the controllers believe: "head" (the phantom's own) or
    /// "fitted-ellipsoid" (the ellipsoid fitted to the phantom's scalp, while the world stays
    /// the scalp: what an ellipsoid lets through). ["head"]
    pub loop_head: LoopHead,
    /// A stimulator trying a pulse through the gate this many times a second during each
    /// `mocomp` run (the gate as `[session.gate]` says, on the run's goal), each pulse scored
    /// against the goal and, with `[coil] model`, in dose. [none]
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pulses_hz: Option<f64>,
}

/// The head model the experiment's controllers believe.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LoopHead {
    /// The phantom's own head model.
    #[default]
    Head,
    /// The ellipsoid fitted to the phantom's scalp.
    FittedEllipsoid,
}

impl LoopHead {
    /// From its name in the file ("head", "fitted-ellipsoid").
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "head" => Ok(Self::Head),
            "fitted-ellipsoid" => Ok(Self::FittedEllipsoid),
            other => Err(format!(
                "{other:?}: the head model is \"head\" or \"fitted-ellipsoid\""
            )),
        }
    }
}

impl Default for ExperimentSection {
    fn default() -> Self {
        Self {
            duration_s: 30.0,
            seed: None,
            head_robot: None,
            head_host: IpAddr::from([127, 0, 0, 3]),
            goal_e2_from_e1_mm: PAPER_GOAL_E2_FROM_E1_MM,
            paper: PaperController::default(),
            contact: false,
            goal_near_mm: None,
            loop_head: LoopHead::Head,
            pulses_hz: None,
        }
    }
}

/// The paper's goal between the end-effectors, `E2_T_E1,g` (translation in mm): the
/// experiment's.
pub use mocomp_experiment::experiment::PAPER_GOAL_E2_FROM_E1_MM;

impl Config {
    /// Parses and checks a configuration's text; errors name `path` and the key. Relative paths
    /// in it (a recorded motion) are relative to `path`'s directory.
    pub fn parse(path: &str, text: &str) -> Result<Self, AppError> {
        let one_line = |e: &dyn std::fmt::Display| e.to_string().trim_end().replace('\n', " ");
        let de = toml::Deserializer::parse(text)
            .map_err(|e| AppError::Config(format!("{path}: {}", one_line(&e))))?;
        // The key's whole path in the message (`tracker.timestamps`), not just its line.
        let mut f: Self = serde_path_to_error::deserialize(de).map_err(|e| {
            AppError::Config(format!("{path}: {}: {}", e.path(), one_line(e.inner())))
        })?;
        let dir = Path::new(path).parent().unwrap_or(Path::new(""));
        f.tracker
            .simulated
            .motion
            .load_file(dir)
            .map_err(|e| AppError::Config(format!("{path}: tracker.simulated.motion.path: {e}")))?;
        f.check().map_err(|e| match e {
            AppError::Config(m) => AppError::Config(format!("{path}: {m}")),
            other => other,
        })?;
        Ok(f)
    }

    /// Checks every value the components do not check themselves, and theirs; errors name the
    /// key.
    pub fn check(&self) -> Result<(), AppError> {
        let cfg =
            |e: &dyn std::fmt::Display, section: &str| AppError::Config(format!("{section}{e}"));
        self.calibrate.check()?;
        self.params.validate().map_err(|e| cfg(&e, "loop."))?;
        self.predictor
            .validate()
            .map_err(|e| cfg(&e, "predictor."))?;
        self.realtime.validate().map_err(|e| cfg(&e, ""))?;
        if self.tracker.source == TrackerSource::Openigtlink && self.tracker.igtl.is_none() {
            return Err(AppError::Config(
                "tracker.igtl: needed (host:port) for source \"openigtlink\"".into(),
            ));
        }
        Check::range(
            "tracker.fixed_latency_s",
            self.tracker.fixed_latency_s,
            0.0,
            1.0,
            false,
        )?;
        let cam = &self.tracker.camera;
        Check::range("tracker.camera.rate_hz", cam.rate_hz, 1.0, 120.0, false)?;
        cam.params
            .validate("tracker.camera.params")
            .map_err(|e| AppError::Config(e.to_string()))?;
        let k = &self.tracker.k4a;
        if !matches!(k.fps, 5 | 15 | 30) || k.fps > k.depth_mode.max_fps() {
            return Err(AppError::Config(format!(
                "tracker.k4a.fps = {}: the camera runs at 5, 15 or 30 frames a second ({:?}: at most {})",
                k.fps,
                k.depth_mode,
                k.depth_mode.max_fps()
            )));
        }
        if !k.depth_mode.has_depth() {
            return Err(AppError::Config(
                "tracker.k4a.depth_mode = \"passive_ir\": the pipeline needs depth".into(),
            ));
        }
        Check::range(
            "tracker.k4a.least_delay_s",
            k.least_delay_s,
            0.0,
            1.0,
            false,
        )?;
        k.params
            .validate("tracker.k4a.params")
            .map_err(|e| AppError::Config(e.to_string()))?;
        let s = &self.tracker.simulated;
        s.motion
            .validate()
            .map_err(|e| cfg(&e, "tracker.simulated.motion."))?;
        s.model
            .validate()
            .map_err(|e| cfg(&e, "tracker.simulated.model."))?;
        s.operator.validate().map_err(|e| {
            AppError::Config(format!("tracker.simulated.operator.{}: {}", e.key, e.why))
        })?;
        self.registration.validate()?;
        Check::non_negative("duration_s", self.duration_s)?;
        Check::range("head.max_tre_mm", self.head.max_tre_mm, 0.0, 50.0, false)?;
        Check::range("ros2.publish_hz", self.ros2.publish_hz, 0.0, 1000.0, false)?;
        if !self.ros2.head_topic.starts_with('/') {
            return Err(AppError::Config(format!(
                "ros2.head_topic {:?}: a topic name starts with /",
                self.ros2.head_topic
            )));
        }
        self.session
            .params()
            .validate()
            .map_err(|e| AppError::Config(format!("session.{e}")))?;
        if self.session.params().gate.max_dose_error_pct.is_some() && self.coil.model.is_none() {
            return Err(AppError::Config(
                "session.gate.max_dose_error_pct: the gate judges the dose, which needs \
                 coil.model (a SimNIBS .ccd file)"
                    .into(),
            ));
        }
        Check::range(
            "session.simulated_stimulator.rate_hz",
            self.session.simulated_stimulator.rate_hz,
            0.0,
            50.0,
            false,
        )?;
        for (key, v) in [
            (
                "session.stimulator_output_pct",
                self.session.stimulator_output_pct,
            ),
            (
                "session.simulated_stimulator.output_pct",
                self.session.simulated_stimulator.output_pct,
            ),
        ] {
            if let Some(v) = v {
                Check::range(key, v, 0.0, 100.0, false)?;
            }
        }
        if self.session.target.is_some() && self.session.targets.is_none() {
            return Err(AppError::Config(
                "session.target: needs session.targets (the file it is in)".into(),
            ));
        }
        // A pulse log no pulse can reach stays empty (`session_wiring` names the rest).
        if self.session.pulse_log.is_some()
            && self.session.pulse_input.is_none()
            && self.session.igtl_device.is_none()
        {
            return Err(AppError::Config(
                "session.pulse_log: no pulse can reach it: set session.pulse_input (the robot \
                 input the stimulator's pulse comes in on) or session.igtl_device (pulses as \
                 OpenIGTLink STRING \"pulse\")"
                    .into(),
            ));
        }
        for (i, r) in self.head.radii_m.iter().enumerate() {
            Check::positive(&format!("head.radii_m[{i}]"), *r)?;
        }
        Check::positive("coil.radius_m", self.coil.radius_m)?;
        Check::positive("coil.thickness_m", self.coil.thickness_m)?;
        crate::coil_config::check(&self.coil)?;
        Check::range(
            "servo.lookahead_s",
            self.servo.lookahead_s,
            0.03,
            0.2,
            false,
        )?;
        Check::range("servo.gain", self.servo.gain, 100.0, 2000.0, false)?;
        self.robot
            .host
            .parse::<IpAddr>()
            .map_err(|e| AppError::Config(format!("robot.host {:?}: {e}", self.robot.host)))?;
        Ok(())
    }

    /// Whether the world is the built-in simulation (robot and tracker), where the frames have
    /// defaults.
    pub fn simulated_world(&self) -> bool {
        self.robot.simulate && self.tracker.source.simulated()
    }

    /// base_from_tracker: the calibration file (relative to `dir`), the inline pose, or (in the
    /// simulated world) [`SIM_BASE_FROM_TRACKER`].
    pub fn base_from_tracker(&self, dir: &Path) -> Result<Isometry3<f64>, AppError> {
        if let Some(file) = &self.calibration.file {
            let path = dir.join(file);
            let what = || format!("calibration.file {}", path.display());
            let text = std::fs::read_to_string(&path).what(what)?;
            let c = mocomp_calib::CalibrationFile::from_toml_str(&text).what(what)?;
            return Ok(c.transforms().what(what)?.1);
        }
        if let Some(y) = &self.calibration.base_from_tracker {
            return Ok(y.iso());
        }
        if self.tracker.source.simulated() {
            return Ok(pose_const(SIM_BASE_FROM_TRACKER).iso());
        }
        Err(AppError::Config(
            "calibration: a real tracker needs its calibration: give `file` (a calibration \
             result) or `base_from_tracker`"
                .into(),
        ))
    }

    /// flange_from_coil: as configured, or (on a simulated robot) [`SIM_FLANGE_FROM_COIL`].
    pub fn flange_from_coil(&self) -> Result<Isometry3<f64>, AppError> {
        match (&self.calibration.flange_from_coil, self.robot.simulate) {
            (Some(p), _) => Ok(p.iso()),
            (None, true) => Ok(pose_const(SIM_FLANGE_FROM_COIL).iso()),
            (None, false) => Err(AppError::Config(
                "calibration.flange_from_coil: a real robot needs the coil's measured mounting"
                    .into(),
            )),
        }
    }

    /// head_from_coil: as configured, or (with the simulated tracker) [`SIM_HEAD_FROM_COIL`].
    pub fn head_from_coil(&self) -> Result<Isometry3<f64>, AppError> {
        match (&self.goal.head_from_coil, self.tracker.source) {
            (Some(p), _) => Ok(p.iso()),
            (None, TrackerSource::Simulated | TrackerSource::Camera) => {
                Ok(pose_const(SIM_HEAD_FROM_COIL).iso())
            }
            (None, TrackerSource::Openigtlink | TrackerSource::Ros2 | TrackerSource::K4a) => {
                Err(AppError::Config(
                    "goal.head_from_coil: a real head needs its goal (teach it: mocomp teach-goal)"
                        .into(),
                ))
            }
        }
    }

    /// A note when the predictor is told another noise than the simulated tracker has (for a
    /// session on the simulated tracker, and the experiment): its adaptive noise scale then reads
    /// the difference as motion and the coil jitters.
    pub fn predictor_note(&self) -> Option<String> {
        let (p, t) = (&self.predictor, &self.tracker.simulated.model);
        let differs = |a: f64, b: f64| (a - b).abs() > 1e-3 * b.abs().max(1e-12);
        (differs(p.position_noise_m, t.noise_m) || differs(p.rotation_noise_rad, t.noise_rad)).then(
            || {
                format!(
                    "predictor.position_noise_m = {}, rotation_noise_rad = {}, but the simulated \
                     tracker's noise is {} m, {} rad (tracker.simulated.model): the predictor \
                     should be told the tracker's noise",
                    p.position_noise_m, p.rotation_noise_rad, t.noise_m, t.noise_rad
                )
            },
        )
    }

    /// A warning when the scalp of `[head] mesh` was segmented from a scan that ends inside
    /// the head anywhere but at the neck: the model is flat there while the real head (an ear,
    /// the brow) goes on, and goals near those faces are refused. In full when the scan was
    /// segmented now; a line when its scalp was kept from before (the user has read it, and a
    /// goal refused there says why itself).
    pub fn head_note(&self) -> Option<String> {
        let head = self.head.loaded.as_ref()?;
        let sides: Vec<&str> = head
            .scan_cuts()
            .iter()
            .map(|c| c.side)
            .filter(|s| *s != "inferior")
            .collect();
        let kept = self.head.scalp_from == Some(crate::head_file::ScalpFrom::Kept);
        (!sides.is_empty()).then(|| {
            if kept {
                return format!(
                    "the scan of [head] mesh ends inside the head at its {} face{} (segmented \
                     before; goals near them are refused)",
                    sides.join(", "),
                    if sides.len() == 1 { "" } else { "s" },
                );
            }
            format!(
                "the scan of [head] mesh ends inside the head at its {} face{}: the model is the \
                 scan's flat face there, not the patient, and a goal whose coil comes within {:.0} \
                 mm of it is refused (a scan that holds the whole head avoids this)",
                sides.join(", "),
                if sides.len() == 1 { "" } else { "s" },
                mocomp_control::goal::SCAN_CUT_KEEP_M * 1e3
            )
        })
    }

    /// The loop's configuration around `base_from_tracker`, at the robot's `period`.
    pub fn loop_config(
        &self,
        base_from_tracker: Isometry3<f64>,
        period: f64,
    ) -> Result<LoopConfig, AppError> {
        let mut cfg = LoopConfig::new(
            base_from_tracker,
            self.flange_from_coil()?,
            self.head_from_coil()?,
            period,
        );
        cfg.servo = ServoParams {
            time_s: period,
            lookahead_s: self.servo.lookahead_s,
            gain: self.servo.gain,
        };
        cfg.predictor = self.predictor;
        cfg.head = self.head_model()?;
        cfg.coil = self.coil_model();
        cfg.params = self.params;
        Ok(cfg)
    }

    /// `[head]` as the loop's model: the scalp [`Self::load_head`] built, or the ellipsoid.
    pub fn head_model(&self) -> Result<HeadModel, AppError> {
        if let Some(head) = &self.head.loaded {
            return Ok(head.clone());
        }
        if let Some(mesh) = &self.head.mesh {
            return Err(AppError::Config(format!(
                "head.mesh = {}: not loaded (the configuration was not read through a setup)",
                mesh.display()
            )));
        }
        // The ellipsoid is given in the image's frame too, so that a registration moves it.
        HeadModel::ellipsoid(
            self.head.head_from_image.iso() * self.head.head_from_ellipsoid.iso(),
            Vector3::from(self.head.radii_m),
        )
        .map_err(|e| AppError::Config(format!("head.radii_m: {e}")))
    }

    /// Reads `[head] landmarks_file` (relative to `dir`) into `[head.landmarks]`, which keeps
    /// its own where both name a landmark; the path becomes the one read (reading it again adds
    /// nothing).
    pub fn load_landmarks(&mut self, dir: &Path) -> Result<(), AppError> {
        let Some(file) = self.head.landmarks_file.take() else {
            return Ok(());
        };
        let path = dir.join(&file);
        let name = path.display().to_string();
        let text = std::fs::read_to_string(&path)
            .map_err(|e| AppError::Config(format!("head.landmarks_file = {name}: {e}")))?;
        let read = if name.ends_with(".json") {
            crate::navigator_files::slicer_points(&name, &text)
        } else {
            crate::navigator_files::simnibs_fiducials(&name, &text)
        }
        .map_err(|e| AppError::Config(format!("head.landmarks_file: {e}")))?;
        for l in read {
            let mm: [f64; 3] = (l.point.coords * 1000.0).into();
            self.head.landmarks.entry(l.name).or_insert(mm);
        }
        self.head.landmarks_file = Some(std::fs::canonicalize(&path).unwrap_or(path));
        Ok(())
    }

    /// Reads `[head] registration` (relative to `dir`) once: its head_from_image becomes
    /// `[head]`'s, before the mesh is carried into the marker's frame by it.
    pub fn load_registration(&mut self, dir: &Path) -> Result<(), AppError> {
        let Some(file) = &self.head.registration else {
            return Ok(());
        };
        if self.head.registered.is_some() {
            return Ok(());
        }
        let path = dir.join(file);
        let read = crate::registration_file::load(&path)
            .map_err(|e| AppError::Config(format!("head.registration: {e}")))?;
        let record = read.registration;
        self.head.head_from_image = Pose::try_from(record.head_from_image)
            .map_err(|e| AppError::Config(format!("head.registration: head_from_image: {e}")))?;
        let path = std::fs::canonicalize(&path).unwrap_or(path);
        self.head.registration = Some(path.clone());
        self.head.registered = Some((path, record));
        Ok(())
    }

    /// Reads, mends and builds `[head] mesh` (relative to `dir`) once, in the head marker's
    /// frame (through `[head] registration`'s head_from_image when there is one, read first);
    /// the path becomes the one read. Nothing to do without a mesh or once loaded. `[coil]
    /// model`'s path is made absolute here too (the files a configuration names are found
    /// where it is).
    pub fn load_head(&mut self, dir: &Path) -> Result<(), AppError> {
        self.load_registration(dir)?;
        crate::coil_config::resolve(&mut self.coil, dir)?;
        self.load_landmarks(dir)?;
        let Some(mesh) = &self.head.mesh else {
            return Ok(());
        };
        if self.head.loaded.is_some() {
            return Ok(());
        }
        let path = dir.join(mesh);
        let units = match self.head.units.as_deref() {
            None => None,
            Some(u) => Some(
                mocomp_head::formats::parse_unit(u)
                    .map_err(|e| AppError::Config(format!("head.units = {u:?}: {e}")))?,
            ),
        };
        let segment = self.segment_options()?;
        let (head, from) =
            crate::head_file::load_head(&path, units, &segment, &self.head.head_from_image.iso())?;
        self.head.scalp_from = Some(from);
        // Absolute from now on, so a printed configuration reads the same file wherever it is.
        self.head.mesh = Some(std::fs::canonicalize(&path).unwrap_or(path));
        self.head.loaded = Some(head);
        Ok(())
    }

    /// How `[head]` segments a NIfTI's scalp.
    pub fn segment_options(&self) -> Result<mocomp_mri::SegmentOptions, AppError> {
        mocomp_mri::SegmentOptions::new(self.head.threshold, self.head.max_triangles)
            .map_err(|e| AppError::Config(format!("head.{} = {}: {}", e.option, e.value, e.why)))
    }

    /// `[coil]` as the loop's model.
    pub fn coil_model(&self) -> CoilModel {
        CoilModel {
            radius: self.coil.radius_m,
            thickness: self.coil.thickness_m,
            casing: self.coil.loaded_casing.clone(),
        }
    }
}

/// Keys the experiment does not use (it builds its own scene, calibrates itself and sets its
/// own goal), as dotted paths; a table stands for every key in it.
/// (`record_mcap`, `ros2.node_name` and `ros2.frames` name the demo's recording.)
const NOT_FOR_THE_EXPERIMENT: [&str; 22] = [
    "duration_s",
    "log_csv",
    "robot.simulate",
    "robot.initial_joints_rad",
    "tracker.source",
    "tracker.igtl",
    "tracker.device",
    "tracker.k4a",
    "tracker.timestamps",
    "tracker.fixed_latency_s",
    "tracker.simulated.base_from_head",
    "tracker.simulated.base_from_tracker",
    "tracker.simulated.flange_from_marker",
    "calibration",
    "goal",
    "realtime",
    "session",
    "ros2.enabled",
    "ros2.domain_id",
    "ros2.publish_hz",
    "ros2.head_topic",
    "ros2.service_mapping",
];

/// The keys a configuration's `text` sets, to other values than their defaults, that `mocomp
/// demo` does not use, so the demo can say so instead of ignoring them silently. A key set to its
/// default changes nothing and is not named, so a printed configuration (every key) reads back
/// without a note. Text that does not parse gives none (the parse says why elsewhere).
pub fn unused_by_experiment(text: &str) -> Vec<String> {
    let Ok(user) = text.parse::<toml::Table>() else {
        return Vec::new();
    };
    let defaults = toml::Table::try_from(Config::default()).unwrap_or_default();
    let mut leaves = Vec::new();
    flatten("", &user, &mut leaves);
    leaves
        .into_iter()
        .filter(|(path, _)| {
            let in_unused = NOT_FOR_THE_EXPERIMENT
                .iter()
                .any(|k| path == k || path.starts_with(&format!("{k}.")));
            // Of [calibrate], the experiment takes the number of poses and samples only.
            let calibrate = path.starts_with("calibrate.")
                && !matches!(
                    path.as_str(),
                    "calibrate.poses" | "calibrate.samples_per_pose"
                );
            in_unused || calibrate
        })
        .filter(|(path, v)| lookup(&defaults, path).is_none_or(|d| !same_value(d, v)))
        .map(|(path, _)| path)
        .collect()
}

/// Every value in `t` that is not a table, with its dotted path.
fn flatten(prefix: &str, t: &toml::Table, out: &mut Vec<(String, toml::Value)>) {
    for (k, v) in t {
        let path = if prefix.is_empty() {
            k.clone()
        } else {
            format!("{prefix}.{k}")
        };
        match v {
            toml::Value::Table(sub) => flatten(&path, sub, out),
            other => out.push((path, other.clone())),
        }
    }
}

fn lookup<'a>(t: &'a toml::Table, path: &str) -> Option<&'a toml::Value> {
    let mut parts = path.split('.');
    let mut v = t.get(parts.next()?)?;
    for p in parts {
        v = v.as_table()?.get(p)?;
    }
    Some(v)
}

/// Equal as configuration values: `0` and `0.0` are the same number.
fn same_value(a: &toml::Value, b: &toml::Value) -> bool {
    use toml::Value::{Array, Float, Integer};
    match (a, b) {
        (Integer(x), Float(y)) | (Float(y), Integer(x)) => (*x as f64) == *y,
        (Array(x), Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(a, b)| same_value(a, b))
        }
        _ => a == b,
    }
}

impl CollectSection {
    /// Checks every value; errors name the key.
    pub fn check(&self) -> Result<(), AppError> {
        let key = |k: &str| format!("calibrate.{k}");
        Check::at_least(&key("poses"), self.poses, 3)?;
        Check::at_least(&key("samples_per_pose"), self.samples_per_pose, 1)?;
        for (k, v) in [
            ("min_rotation_rad", self.min_rotation_rad),
            ("spread_m", self.spread_m),
            ("settle_s", self.settle_s),
        ] {
            Check::non_negative(&key(k), v)?;
        }
        // Zero noise would weight the solver's residuals infinitely.
        for (k, v) in [
            ("tracker_noise_m", self.tracker_noise_m),
            ("tracker_noise_rad", self.tracker_noise_rad),
            ("robot_noise_m", self.robot_noise_m),
            ("robot_noise_rad", self.robot_noise_rad),
        ] {
            Check::positive(&key(k), v)?;
        }
        Check::range(
            &key("max_rotation_rad"),
            self.max_rotation_rad,
            self.min_rotation_rad,
            std::f64::consts::PI,
            true,
        )?;
        for (k, v, hi) in [
            ("joint_speed_rad_s", self.joint_speed_rad_s, 3.0),
            ("joint_accel_rad_s2", self.joint_accel_rad_s2, 40.0),
            ("move_timeout_s", self.move_timeout_s, 600.0),
        ] {
            Check::range(&key(k), v, 0.0, hi, true)?;
        }
        Ok(())
    }
}

/// The configuration, read and checked, with what follows from it.
#[derive(Debug, Clone)]
pub struct Setup {
    /// The configuration.
    pub file: Config,
    /// Where it came from (`None`: the defaults alone).
    pub path: Option<PathBuf>,
    /// Its directory (relative paths in it are relative to this).
    pub dir: PathBuf,
    /// The robot model.
    pub model: Model,
    /// Its kinematics (flange).
    pub arm: Arm,
    /// The configured base_from_tracker (the calibration).
    pub base_from_tracker: Isometry3<f64>,
}

impl Setup {
    /// Reads and checks the file at `path`.
    pub fn load(path: &Path) -> Result<Self, AppError> {
        Self::load_with(path, |_| {})
    }

    /// [`Setup::load`], with `edit` applied to the file as read, before it is checked: a
    /// command line's options that override the file are checked as the file's own values
    /// are, and the checked setup is never edited afterwards.
    pub fn load_with(path: &Path, edit: impl FnOnce(&mut Config)) -> Result<Self, AppError> {
        let text = std::fs::read_to_string(path).what(|| format!("--config {}", path.display()))?;
        let mut file = Config::parse(&path.display().to_string(), &text)?;
        edit(&mut file);
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Self::new(file, Some(path.to_path_buf()), dir)
    }

    /// A setup of a configuration already read (its relative paths relative to `dir`).
    pub fn new(mut file: Config, path: Option<PathBuf>, dir: PathBuf) -> Result<Self, AppError> {
        file.check()?;
        file.load_head(&dir)?;
        let model = file.robot.model;
        let base_from_tracker = file.base_from_tracker(&dir)?;
        // The coil's mounting, named now rather than once the robot moves (the goal may be
        // missing yet: teaching it is what `teach-goal` is for).
        file.flange_from_coil()?;
        Ok(Self {
            file,
            path,
            dir,
            model,
            arm: Arm::new(model),
            base_from_tracker,
        })
    }

    /// Refuses `tracker.source = "ros2"` for `job`, which reads the tracker over OpenIGTLink.
    pub fn needs_igtl_tracker(&self, job: &str) -> Result<(), AppError> {
        if self.file.tracker.source == TrackerSource::Ros2 {
            return Err(AppError::Config(format!(
                "tracker.source = \"ros2\": {job} reads the tracker over OpenIGTLink (only \
                 `mocomp run` takes the head's poses from ROS 2)"
            )));
        }
        Ok(())
    }

    /// The robot's control period, s.
    pub fn period(&self) -> f64 {
        self.model.spec().series.period_s()
    }

    /// The loop's configuration.
    pub fn loop_config(&self) -> Result<LoopConfig, AppError> {
        self.file.loop_config(self.base_from_tracker, self.period())
    }

    /// The simulated robot's joints at start: `robot.initial_joints_rad`, or the coil 15 cm out
    /// on the goal's axis for the head at rest.
    pub fn initial_joints(&self) -> Result<[f64; 6], AppError> {
        self.initial_joints_at(&self.file.tracker.simulated.base_from_head.iso())
    }

    /// [`Self::initial_joints`] with the head at `rest` (a placement tried).
    pub fn initial_joints_at(&self, rest: &Isometry3<f64>) -> Result<[f64; 6], AppError> {
        if let Some(q) = self.file.robot.initial_joints_rad {
            return Ok(q);
        }
        let cfg = self.loop_config()?;
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
            if let Ok(c) = self.arm.ik_closest(&out, &seed, &Selection::tracking(0.1)) {
                return Ok(c.joints);
            }
        }
        Err(AppError::Config(
            "robot.initial_joints_rad: needed, the default start (15 cm out on the goal's axis) \
             is out of reach"
                .into(),
        ))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn parse(text: &str) -> Result<Config, AppError> {
        Config::parse("f.toml", text)
    }

    #[test]
    fn bad_files_are_refused_naming_the_file_and_the_key() {
        let cases = [
            ("duraton_s = 3\n", "duraton_s"),
            ("[tracker]\nnoise = 1\n", "tracker.noise"),
            ("[robot]\nmodel = \"ur4\"\n", "robot.model"),
            ("[robot]\nhost = \"robot.local\"\n", "robot.host"),
            ("duration_s = -1.0\n", "duration_s"),
            ("[tracker.simulated.motion]\nsway_m = 0.01\n", "kind"),
            (
                "[tracker.simulated.motion]\nkind = \"nods\"\nsway_m = -0.01\n",
                "tracker.simulated.motion.sway_m",
            ),
            ("[servo]\ngain = 50.0\n", "servo.gain"),
            ("[coil]\nradius_m = 0.0\n", "coil.radius_m"),
            ("[calibrate]\nposes = 2\n", "calibrate.poses"),
            (
                "[calibrate]\nmax_rotation_rad = 0.1\n",
                "calibrate.max_rotation_rad",
            ),
            ("[loop]\nspeed_fraction = 2.0\n", "loop.speed_fraction"),
            ("[predictor]\naccel_noise = -1.0\n", "predictor.accel_noise"),
            (
                "[goal]\nhead_from_coil = [0.0, 0.0, 0.1]\n",
                "goal.head_from_coil",
            ),
            (
                "[goal]\nhead_from_coil = [0.0, 0.0, nan, 0.0, 0.0, 0.0]\n",
                "goal.head_from_coil",
            ),
            ("[tracker]\nsource = \"openigtlink\"\n", "tracker.igtl"),
            ("[tracker]\ntimestamps = \"gps\"\n", "tracker.timestamps"),
            ("duration_s = 3\nduration_s = 4\n", "duration_s"),
        ];
        for (text, key) in cases {
            let e = parse(text).unwrap_err();
            assert!(matches!(e, AppError::Config(_)), "{text:?}: {e:?}");
            let e = e.to_string();
            assert!(
                e.starts_with("f.toml: ") && e.contains(key),
                "{text:?}: {e}"
            );
        }
        // Where the TOML itself is at fault, the line is given.
        let e = parse("duration_s = 3\n\n[tracker]\nnoise = 1\n").unwrap_err();
        assert!(e.to_string().contains("line 4"), "{e}");
    }

    #[test]
    fn a_real_setup_must_give_what_has_no_default_there() {
        let real = "[robot]\nsimulate = false\n[tracker]\nsource = \"openigtlink\"\nigtl = \"127.0.0.1:18944\"\n";
        let cfg = parse(real).unwrap();
        let dir = Path::new("");
        let missing = |r: Result<Isometry3<f64>, AppError>| r.unwrap_err().to_string();
        assert!(missing(cfg.base_from_tracker(dir)).contains("calibration"));
        assert!(missing(cfg.flange_from_coil()).contains("calibration.flange_from_coil"));
        assert!(missing(cfg.head_from_coil()).contains("goal.head_from_coil"));
        // The simulated world has them; a value given wins.
        let sim = Config::default();
        assert_eq!(
            sim.head_from_coil().unwrap(),
            iso_from_ur_pose(&SIM_HEAD_FROM_COIL).unwrap()
        );
        let given =
            parse("[goal]\nhead_from_coil = [0.0, 0.0, 0.12, 3.14159, 0.0, 0.0]\n").unwrap();
        assert!((given.head_from_coil().unwrap().translation.z - 0.12).abs() < 1e-12);
    }

    #[test]
    fn a_predictor_told_another_noise_than_the_simulated_trackers_is_noted() {
        assert_eq!(Config::default().predictor_note(), None);
        let cfg = parse("[tracker.simulated.model]\nnoise_rad = 0.0015\n").unwrap();
        let note = cfg.predictor_note().unwrap();
        assert!(
            note.contains("rotation_noise_rad = 0.001") && note.contains("0.0015"),
            "{note}"
        );
    }

    #[test]
    fn the_demo_names_the_keys_it_does_not_use() {
        let keys = unused_by_experiment(
            "duration_s = 3\n[robot]\nmodel = \"ur3\"\nsimulate = false\n[goal]\nhead_from_coil = [0,0,0.1,3,0,0]\n\
             [calibrate]\nposes = 12\nsettle_s = 0.5\n[realtime]\npriority = 50\n",
        );
        assert_eq!(
            keys,
            [
                "calibrate.settle_s",
                "duration_s",
                "goal.head_from_coil",
                "robot.simulate"
            ]
        );
        assert!(unused_by_experiment("[robot]\nmodel = \"ur3\"\n").is_empty());
        // A key at its default changes nothing (0 and 0.0 alike).
        assert!(unused_by_experiment("duration_s = 0\n").is_empty());
    }
}
