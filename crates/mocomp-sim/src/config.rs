//! The experiment's configuration file (TOML), for `mocomp demo --config`.
//!
//! Every key is optional: what a file leaves out keeps the value it had (the defaults of
//! [`ExperimentConfig::new`], which `mocomp demo --print-config` prints as a file). Within a
//! section the same holds key by key, except `[motion]`, which is whole: its `kind` chooses the
//! motion and the kind's own defaults fill the rest. Unknown keys are rejected, and every error
//! names the key (and, where the file is at fault, its line).
//!
//! ```toml
//! seconds = 30.0
//! seed = 1                  # the random motion's and the tracker noise's
//!
//! [robots]
//! coil = "ur3"              # U1, carries the coil
//! head = "ur5"              # U2, carries the head phantom
//!
//! [motion]
//! kind = "nods"             # still | drift | nods | random
//! sway_m = 0.01
//!
//! [tracker]
//! noise_m = 0.0002
//! ```

use crate::experiment::{ExperimentConfig, ExperimentError, PaperController};
use crate::motion::HeadMotion;
use crate::tracker::TrackerModel;
use mocomp_control::{LoopParams, PredictorConfig};
use mocomp_geom::nalgebra::Matrix4;
use mocomp_geom::{iso_from_matrix_mm, matrix_mm_from_iso};
use mocomp_kin::Model;
use serde::{Deserialize, Serialize};
use std::net::IpAddr;

/// The robots and their loopback addresses.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotsSection {
    /// U1's model, which carries the coil (`ur3`, `ur5e`, …).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coil: Option<String>,
    /// U2's model, which carries the head phantom.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head: Option<String>,
    /// U1's simulator's address (loopback).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coil_host: Option<IpAddr>,
    /// U2's simulator's address (loopback).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub head_host: Option<IpAddr>,
}

/// The hand-eye calibration at the start.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationSection {
    /// Poses per robot.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub poses: Option<usize>,
    /// Tracker samples averaged at each pose.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub samples: Option<usize>,
}

/// The file. Scalars first: TOML puts tables after them.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentFile {
    /// Compensation time per controller, s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seconds: Option<f64>,
    /// Seeds the random motion and the tracker's noise (overrides their own `seed` keys).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// The goal between the end-effectors `E2_T_E1,g`, rows of a 4×4 matrix with translation in
    /// mm (the paper's by default).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub goal_e2_from_e1_mm: Option<[[f64; 4]; 4]>,
    /// The robots.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub robots: Option<RobotsSection>,
    /// The calibration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub calibration: Option<CalibrationSection>,
    /// The head's motion.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion: Option<HeadMotion>,
    /// The tracker.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tracker: Option<TrackerModel>,
    /// The `paper` controller.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub paper: Option<PaperController>,
    /// The `mocomp` loop's predictor.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub predictor: Option<PredictorConfig>,
    /// The `mocomp` loop's parameters.
    #[serde(rename = "loop", skip_serializing_if = "Option::is_none")]
    pub loop_params: Option<LoopParams>,
}

fn config_err(e: impl std::fmt::Display) -> ExperimentError {
    ExperimentError::Config(e.to_string())
}

impl ExperimentFile {
    /// Every setting of `cfg`, as a file.
    pub fn from_config(cfg: &ExperimentConfig) -> Self {
        // The paper's goal as printed in the paper (it reads back to the same transform).
        let paper = crate::experiment::paper_goal().ok();
        let goal = if paper == Some(cfg.goal_e2_from_e1) {
            crate::experiment::PAPER_GOAL_E2_FROM_E1_MM
        } else {
            let m = matrix_mm_from_iso(&cfg.goal_e2_from_e1);
            std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
        };
        Self {
            seconds: Some(cfg.duration_s),
            seed: None,
            goal_e2_from_e1_mm: Some(goal),
            robots: Some(RobotsSection {
                coil: Some(cfg.coil_robot.name().to_string()),
                head: Some(cfg.head_robot.name().to_string()),
                coil_host: Some(cfg.coil_host),
                head_host: Some(cfg.head_host),
            }),
            calibration: Some(CalibrationSection {
                poses: Some(cfg.calibration_poses),
                samples: Some(cfg.calibration_samples),
            }),
            motion: Some(cfg.motion.clone()),
            tracker: Some(cfg.tracker),
            paper: Some(cfg.paper),
            predictor: Some(cfg.predictor),
            loop_params: Some(cfg.loop_params),
        }
    }

    /// Sets what the file sets. Sections are whole here: [`apply_toml`] fills them first.
    fn apply(&self, cfg: &mut ExperimentConfig) -> Result<(), ExperimentError> {
        if let Some(s) = self.seconds {
            cfg.duration_s = s;
        }
        if let Some(g) = self.goal_e2_from_e1_mm {
            let m = Matrix4::from_fn(|r, c| g[r][c]);
            cfg.goal_e2_from_e1 = iso_from_matrix_mm(&m, 5e-3)
                .map_err(|e| config_err(format!("goal_e2_from_e1_mm: {e}")))?;
        }
        if let Some(r) = &self.robots {
            let model = |key: &str, name: &Option<String>, into: &mut Model| {
                if let Some(n) = name {
                    *into = n
                        .parse()
                        .map_err(|e| config_err(format!("robots.{key}: {e}")))?;
                }
                Ok::<(), ExperimentError>(())
            };
            model("coil", &r.coil, &mut cfg.coil_robot)?;
            model("head", &r.head, &mut cfg.head_robot)?;
            if let Some(h) = r.coil_host {
                cfg.coil_host = h;
            }
            if let Some(h) = r.head_host {
                cfg.head_host = h;
            }
        }
        if let Some(c) = &self.calibration {
            cfg.calibration_poses = c.poses.unwrap_or(cfg.calibration_poses);
            cfg.calibration_samples = c.samples.unwrap_or(cfg.calibration_samples);
        }
        if let Some(m) = self.motion.clone() {
            cfg.motion = m;
        }
        if let Some(t) = self.tracker {
            cfg.tracker = t;
        }
        if let Some(p) = self.paper {
            cfg.paper = p;
        }
        if let Some(p) = self.predictor {
            cfg.predictor = p;
        }
        if let Some(l) = self.loop_params {
            cfg.loop_params = l;
        }
        if let Some(seed) = self.seed {
            cfg.set_seed(seed);
        }
        Ok(())
    }

    /// The file as TOML.
    pub fn to_toml(&self) -> Result<String, ExperimentError> {
        toml::to_string(self).map_err(config_err)
    }
}

/// Overlays `user` on `base`, key by key within tables (a `motion` table replaces whole).
fn overlay(base: &mut toml::Table, user: toml::Table, top: bool) {
    for (k, v) in user {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(u)) if !(top && k == "motion") => {
                overlay(b, u, false);
            }
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// Applies a configuration file's text to `cfg`, then checks the result. The error names the
/// key, and the line where the file is at fault; `cfg` is unchanged on error.
pub fn apply_toml(text: &str, cfg: &mut ExperimentConfig) -> Result<(), ExperimentError> {
    // Strictly first, for errors with lines: unknown keys, wrong types.
    let _: ExperimentFile = toml::from_str(text).map_err(config_err)?;
    let user: toml::Table = text.parse().map_err(config_err)?;
    // Then each section over the current values, key by key.
    let mut merged = toml::Table::try_from(ExperimentFile::from_config(cfg)).map_err(config_err)?;
    overlay(&mut merged, user, true);
    let file: ExperimentFile = toml::Value::Table(merged).try_into().map_err(config_err)?;
    let mut next = cfg.clone();
    file.apply(&mut next)?;
    next.validate()?;
    *cfg = next;
    Ok(())
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::motion::Nods;

    #[test]
    fn the_printed_defaults_read_back_to_the_same_configuration() {
        let cfg = ExperimentConfig::new().unwrap();
        let text = ExperimentFile::from_config(&cfg).to_toml().unwrap();
        let mut back = ExperimentConfig::new().unwrap();
        // Start from something else, so the file has to set every value.
        back.duration_s = 1.0;
        back.coil_robot = Model::Ur10;
        back.motion = HeadMotion::Still;
        back.tracker.noise_m = 1.0;
        back.paper.period_s = 1.0;
        back.predictor.angular_accel_noise = 1.0;
        back.loop_params.speed_fraction = 0.1;
        back.calibration_poses = 3;
        back.goal_e2_from_e1 = mocomp_geom::nalgebra::Isometry3::identity();
        apply_toml(&text, &mut back).unwrap();
        let err = mocomp_geom::translation_error(&back.goal_e2_from_e1, &cfg.goal_e2_from_e1)
            + mocomp_geom::rotation_error(&back.goal_e2_from_e1, &cfg.goal_e2_from_e1);
        assert!(err < 1e-12, "{err}");
        back.goal_e2_from_e1 = cfg.goal_e2_from_e1;
        assert_eq!(back, cfg, "{text}");
    }

    #[test]
    fn a_section_sets_only_its_keys_and_the_seed_reaches_motion_and_tracker() {
        let mut cfg = ExperimentConfig::new().unwrap();
        let before = cfg.clone();
        apply_toml(
            "seed = 9\n[predictor]\nmax_horizon_s = 0.1\n[tracker]\nnoise_m = 2e-4\n[robots]\ncoil = \"UR5\"\n",
            &mut cfg,
        )
        .unwrap();
        assert_eq!(cfg.predictor.max_horizon_s, 0.1);
        // The experiment's own predictor tuning stays (not PredictorConfig's default).
        assert_eq!(
            cfg.predictor.angular_accel_noise,
            before.predictor.angular_accel_noise
        );
        assert_eq!(cfg.tracker.noise_m, 2e-4);
        assert_eq!(cfg.tracker.rate_hz, before.tracker.rate_hz);
        assert_eq!(cfg.tracker.seed, 9);
        assert!(matches!(cfg.motion, HeadMotion::Random(r) if r.seed == 9));
        assert_eq!(cfg.coil_robot, Model::Ur5);
        assert_eq!(cfg.head_robot, before.head_robot);
    }

    #[test]
    fn a_motion_is_whole_with_its_kinds_defaults() {
        let mut cfg = ExperimentConfig::new().unwrap();
        apply_toml("[motion]\nkind = \"nods\"\nsway_m = 0.01\n", &mut cfg).unwrap();
        assert_eq!(
            cfg.motion,
            HeadMotion::Nods(Nods {
                sway_m: 0.01,
                ..Nods::default()
            })
        );
    }

    #[test]
    fn bad_files_are_refused_naming_the_key_and_change_nothing() {
        let cases = [
            ("secnds = 3\n", "secnds"),
            ("[tracker]\nnoise = 1\n", "noise"),
            ("[robots]\ncoil = \"ur4\"\n", "robots.coil"),
            ("[robots]\ncoil = \"ur3e\"\n", "robots.coil"),
            ("[robots]\ncoil_host = \"10.0.0.1\"\n", "robots.coil_host"),
            ("seconds = -1.0\n", "seconds"),
            ("[motion]\nsway_m = 0.01\n", "kind"),
            (
                "[motion]\nkind = \"nods\"\nsway_m = -0.01\n",
                "motion.sway_m",
            ),
            ("[paper]\nperiod_s = 0.0\n", "paper.period_s"),
            ("[predictor]\naccel_noise = -1.0\n", "predictor.accel_noise"),
            ("[tracker]\nrate_hz = \"fast\"\n", "rate_hz"),
            (
                "goal_e2_from_e1_mm = [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n",
                "goal_e2_from_e1_mm",
            ),
            ("[calibration]\nposes = 1\n", "calibration.poses"),
            ("seconds = 3\nseconds = 4\n", "seconds"),
        ];
        for (text, key) in cases {
            let mut cfg = ExperimentConfig::new().unwrap();
            let e = apply_toml(text, &mut cfg).unwrap_err().to_string();
            assert!(e.contains(key), "{text:?}: {e}");
            assert_eq!(cfg, ExperimentConfig::new().unwrap(), "{text:?}");
        }
        // Where the file is at fault, the line is given.
        let mut cfg = ExperimentConfig::new().unwrap();
        let e = apply_toml("seconds = 3\n\n[tracker]\nnoise = 1\n", &mut cfg)
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 4"), "{e}");
    }
}
