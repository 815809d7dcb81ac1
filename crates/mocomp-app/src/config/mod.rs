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

mod check;
pub mod coil;
mod collect;
mod experiment;
mod frames;
mod head;
mod pose;
pub mod range;
pub mod reference;
pub mod registration;
pub mod registration_file;
mod robot;
mod ros2;
mod session;
mod setup;
pub mod template;
mod tracker;

pub use collect::*;
pub use experiment::*;
pub use frames::*;
pub use head::*;
pub use pose::*;
pub use robot::*;
pub use ros2::*;
pub use session::*;
pub use setup::*;
pub use tracker::*;

pub use crate::config::coil::CoilSection;
pub use crate::config::range::Check;
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
    pub registration: registration::RegistrationSection,
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
    /// What `[head]`'s files held, once [`Config::load_head`] has read them; not part of the file.
    #[serde(skip)]
    pub loaded: LoadedHead,
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
        cfg.servo = self.servo.params(period);
        cfg.predictor = self.predictor;
        cfg.head = self.head_model()?;
        cfg.coil = self.coil_model();
        cfg.params = self.params;
        Ok(cfg)
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
            (
                "[servo]\nlookahead_s = 0.5\n",
                "servo.lookahead_s = 0.5: must be in [0.03, 0.2]",
            ),
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
