//! `[tracker]`: where the head's poses come from (OpenIGTLink, ROS 2, the simulated tracker,
//! a depth camera, an Azure Kinect).

use super::*;

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

impl TrackerSection {
    /// Its keys' ranges and choices, and its parts' own checks; errors name the key.
    pub(super) fn check(&self) -> Result<(), AppError> {
        if self.source == TrackerSource::Openigtlink && self.igtl.is_none() {
            return Err(AppError::Config(
                "tracker.igtl: needed (host:port) for source \"openigtlink\"".into(),
            ));
        }
        Check::range(
            "tracker.fixed_latency_s",
            self.fixed_latency_s,
            0.0,
            1.0,
            false,
        )?;
        let cam = &self.camera;
        Check::range("tracker.camera.rate_hz", cam.rate_hz, 1.0, 120.0, false)?;
        cam.params
            .validate("tracker.camera.params")
            .map_err(|e| AppError::Config(e.to_string()))?;
        let k = &self.k4a;
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
        let s = &self.simulated;
        s.motion
            .validate()
            .map_err(|e| check::in_section(&e, "tracker.simulated.motion."))?;
        s.model
            .validate()
            .map_err(|e| check::in_section(&e, "tracker.simulated.model."))?;
        s.operator.validate().map_err(|e| {
            AppError::Config(format!("tracker.simulated.operator.{}: {}", e.key, e.why))
        })?;
        Ok(())
    }
}
