//! The experiment's configuration from the one configuration file: the keys of `[experiment]`,
//! and the robot, tracker, loop, head and coil sections the experiment shares with the live
//! session (`mocomp demo`; see [`crate::config::ExperimentSection`]).

use crate::AppError;
use crate::config::{Config, LoopHead};
use mocomp_control::HeadModel;
use mocomp_experiment::experiment::{ExperimentConfig, ExperimentError};
use mocomp_experiment::session_plan::SessionPlan;
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Matrix4, Point3, Vector3};
use mocomp_geom::units::mm_to_m;
use mocomp_head::{Ellipsoid, Head};
use mocomp_kin::Model;
use mocomp_sim::contact::ContactParams;
use std::net::IpAddr;

/// The experiment's defaults: those of the configuration ([`Config`]'s, see
/// [`crate::config::ExperimentSection`]): a UR3 and a UR5 (CB3, 125 Hz) on 127.0.0.2 and
/// 127.0.0.3, 30 s of smooth random motion up to 20 mm/s and 10°/s, a 60 Hz tracker with
/// 20 ms latency and 0.1 mm / 1 mrad noise per axis, 15 calibration poses per robot (10
/// samples averaged at each), the paper's goal.
pub fn defaults() -> Result<ExperimentConfig, ExperimentError> {
    from_config(&Config::default()).map_err(|e| ExperimentError::Config(e.to_string()))
}

/// The experiment's configuration from the one configuration (`mocomp demo`): see
/// [`crate::config::ExperimentSection`] for which keys it takes. Checked; errors name the key.
pub fn from_config(cfg: &Config) -> Result<ExperimentConfig, AppError> {
    let x = &cfg.experiment;
    let coil_host: IpAddr = cfg
        .robot
        .host
        .parse()
        .map_err(|e| AppError::Config(format!("robot.host {:?}: {e}", cfg.robot.host)))?;
    let m = Matrix4::from_fn(|r, c| x.goal_e2_from_e1_mm[r][c]);
    let goal = iso_from_matrix_mm(&m, 5e-3)
        .map_err(|e| AppError::Config(format!("experiment.goal_e2_from_e1_mm: {e}")))?;
    let mut e = ExperimentConfig {
        coil_robot: cfg.robot.model,
        head_robot: x.head_robot.unwrap_or(match cfg.robot.model.spec().series {
            mocomp_kin::Series::Cb3 => Model::Ur5,
            mocomp_kin::Series::ESeries => Model::Ur5e,
        }),
        coil_host,
        head_host: x.head_host,
        duration_s: x.duration_s,
        motion: cfg.tracker.simulated.motion.clone(),
        tracker: cfg.tracker.simulated.model,
        paper: x.paper,
        calibration_poses: cfg.calibrate.poses,
        calibration_samples: cfg.calibrate.samples_per_pose,
        goal_e2_from_e1: goal,
        loop_params: cfg.params,
        predictor: cfg.predictor,
        servo: (cfg.servo.lookahead_s, cfg.servo.gain),
        head: cfg.head_model()?,
        loop_head: None,
        coil_design: mocomp_experiment::experiment::head_from_coil_design(),
        coil: cfg.coil_model(),
        contact: ContactParams {
            noise_n: mocomp_sim::contact::SIMULATED_SENSOR_NOISE_N,
            ..ContactParams::default()
        },
        on_scalp: x.contact,
        tracker_bump: None,
        session: x
            .pulses_hz
            .map(|hz| SessionPlan::pulsing(cfg.session.params(), x.duration_s, hz))
            .transpose()
            .map_err(|m| AppError::Config(format!("experiment.{m}")))?,
        dose: cfg.coil.dose_model()?,
    };
    place_on_head(cfg, &mut e)?;
    if e.on_scalp {
        e.loop_params.force_sensing = true;
        e.loop_params.contact_mode = true;
    }
    if let Some(seed) = x.seed {
        e.set_seed(seed);
    }
    e.validate().map_err(|e| match e {
        ExperimentError::Config(m) => AppError::Config(m),
        other => AppError::failed("the experiment's configuration", other),
    })?;
    Ok(e)
}

/// `[experiment] loop_head` and `goal_near_mm` on the experiment's head. The goal is laid on the
/// head model the controllers believe, as a clinician plans on the model they have: on a fitted
/// ellipsoid it can lie inside the real scalp (an ear), which the true clearance then shows.
fn place_on_head(cfg: &Config, e: &mut ExperimentConfig) -> Result<(), AppError> {
    let x = &cfg.experiment;
    if x.loop_head == LoopHead::FittedEllipsoid {
        let Some(m) = e.head.shape().scalp() else {
            return Err(AppError::Config(
                "experiment.loop_head = \"fitted-ellipsoid\": needs a scalp (head.mesh) to fit"
                    .into(),
            ));
        };
        let fitted = Ellipsoid::fit(m.vertices())
            .map_err(|err| AppError::failed("fitting an ellipsoid to the scalp", err))?;
        e.loop_head = Some(HeadModel::new(Head::Ellipsoid(fitted)));
    }
    if let Some(near) = x.goal_near_mm {
        let p = Point3::from(Vector3::from(near).map(mm_to_m));
        let model = e.loop_head.as_ref().unwrap_or(&e.head);
        e.coil_design =
            mocomp_session::grid::coil_over(model, &p, GOAL_STANDOFF_M).map_err(|err| {
                AppError::Config(format!("experiment.goal_near_mm = {near:?}: {err}"))
            })?;
    }
    Ok(())
}

/// How far off the scalp `goal_near_mm` puts the coil's face, m (the paper's design: 3 mm).
pub const GOAL_STANDOFF_M: f64 = 0.003;

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_sim::HeadMotion;

    #[test]
    fn the_experiment_takes_the_shared_keys() {
        let cfg = Config::parse("f.toml", 
            "[robot]\nmodel = \"ur5e\"\nhost = \"127.0.0.61\"\n[experiment]\nseed = 9\nduration_s = 4.0\n\
             [tracker.simulated.model]\nnoise_m = 0.0002\n[servo]\ngain = 900.0\n[coil]\nradius_m = 0.05\n\
             [calibrate]\nposes = 12\nsamples_per_pose = 4\n",
        )
        .unwrap();
        let e = from_config(&cfg).unwrap();
        assert_eq!((e.coil_robot, e.head_robot), (Model::Ur5e, Model::Ur5e));
        assert_eq!(e.coil_host, IpAddr::from([127, 0, 0, 61]));
        assert_eq!(e.duration_s, 4.0);
        assert_eq!(e.tracker.noise_m, 2e-4);
        // The seed reaches the tracker and the random motion.
        assert_eq!(e.tracker.seed, 9);
        assert!(matches!(e.motion, HeadMotion::Random(r) if r.seed == 9));
        assert_eq!(e.servo.1, 900.0);
        assert_eq!(e.coil.radius, 0.05);
        assert_eq!((e.calibration_poses, e.calibration_samples), (12, 4));
        // Two robots of different series cannot share one stepped clock.
        let bad = Config::parse(
            "f.toml",
            "[robot]\nmodel = \"ur3e\"\n[experiment]\nhead_robot = \"ur5\"\n",
        )
        .unwrap();
        let err = from_config(&bad).unwrap_err().to_string();
        assert!(err.contains("experiment.head_robot"), "{err}");
    }
}
