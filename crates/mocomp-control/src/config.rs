//! The loop's parameters, with their defaults and units.

use crate::geometry::{CoilModel, HeadModel};
use crate::predict::PredictorConfig;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_ur::ServoParams;

/// Everything the compensation loop needs besides the robot and the tracker.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopConfig {
    /// `Y`: base_from_tracker (from calibration).
    pub base_from_tracker: Isometry3<f64>,
    /// `X` for the coil: flange_from_coil (the coil's mounting on the flange).
    pub flange_from_coil: Isometry3<f64>,
    /// The goal: head_from_coil (taught or configured).
    pub head_from_coil_goal: Isometry3<f64>,
    /// servoj parameters (time = the controller period).
    pub servo: ServoParams,
    /// Predict the head pose to the time the command acts (else use the newest sample as is,
    /// like the seed paper).
    pub predict: bool,
    /// The predictor's noise model.
    pub predictor: PredictorConfig,
    /// Keep this far inside every joint limit, rad. [0.05]
    pub joint_margin_rad: f64,
    /// Fraction of each joint's maximum speed the loop may command. [0.5]
    pub speed_fraction: f64,
    /// Joint acceleration limit of the command, rad/s². [12]
    pub max_joint_accel: f64,
    /// TCP (coil) speed limit, m/s. [0.25]
    pub max_tcp_speed: f64,
    /// Beyond this deviation of the flange from its goal (m) the loop plans a path instead of
    /// servoing straight. [0.02]
    pub servo_deviation_m: f64,
    /// Beyond this rotation from the goal (rad) the loop plans a path. [0.7, about 40°]
    pub plan_rotation_rad: f64,
    /// Distance from the head the planned path keeps while travelling around it, m. [0.05]
    pub shell_distance_m: f64,
    /// Coil speed along a planned path, m/s (rotation: 0.1 m per rad). [0.05]
    pub approach_speed_m_s: f64,
    /// Acceleration along a planned path, m/s². [0.2]
    pub approach_accel_m_s2: f64,
    /// The path waits while the command lags its point by more than this, m. [0.005]
    pub path_lag_m: f64,
    /// Tracker sample older than this (s, by its acquisition time) holds the robot: 75 ms lets a
    /// 60 Hz tracker with 20 ms latency lose one sample. [0.075]
    pub tracker_stale_s: f64,
    /// This many identical consecutive samples mean a frozen tracker stream. [20]
    pub frozen_samples: u32,
    /// A sample implying a head speed above this (m/s) is an outlier and ignored. [1.0]
    pub outlier_speed_m_s: f64,
    /// A sample implying an angular speed above this (rad/s) is an outlier. [10]
    pub outlier_speed_rad_s: f64,
    /// Head speed above this (m/s) holds the robot instead of chasing. [0.15]
    pub max_head_speed_m_s: f64,
    /// Head angular speed above this (rad/s) holds the robot. [1.2, about 70°/s]
    pub max_head_speed_rad_s: f64,
    /// A fault must have been clear this long before tracking resumes, s. [0.2]
    pub resume_after_s: f64,
    /// Robot state older than this many controller periods is stale. [5]
    pub robot_stale_periods: f64,
    /// Singularity margin below which the loop slows down (see `Singularity::margin`). [0.1]
    pub singularity_slow: f64,
    /// Singularity margin below which the loop holds. [0.02]
    pub singularity_hold: f64,
    /// Deceleration used when the robot is stopped by the loop, rad/s². [4]
    pub stop_decel: f64,
    /// The head's collision model.
    pub head: HeadModel,
    /// The coil's collision model.
    pub coil: CoilModel,
    /// The coil's closest allowed distance to the scalp, m: 0 lets it touch, never enter.
    /// A goal closer than this is refused. [0]
    pub coil_min_distance_m: f64,
    /// Below `coil_min_distance_m`, the depth the coil may still move within (the scalp's and
    /// hair's give), m: a head that moves into a lagging coil must not lock it in place. Deeper
    /// than this, motions that go deeper are refused. [0.002]
    pub coil_contact_tolerance_m: f64,
    /// Closest distance any arm link may come to the head, m. [0.01]
    pub link_clearance_m: f64,
    /// Link capsule radius, m. [0.045]
    pub link_radius_m: f64,
    /// Within `approach_zone_m` of the head the coil must stay within this of its approach axis
    /// (the goal's z axis), m. [0.01]
    pub approach_tolerance_m: f64,
    /// Thickness of the zone around the head where the approach rule applies, m. [0.03]
    pub approach_zone_m: f64,
}

impl LoopConfig {
    /// Defaults around the given frames.
    pub fn new(
        base_from_tracker: Isometry3<f64>,
        flange_from_coil: Isometry3<f64>,
        head_from_coil_goal: Isometry3<f64>,
        period_s: f64,
    ) -> Self {
        Self {
            base_from_tracker,
            flange_from_coil,
            head_from_coil_goal,
            servo: ServoParams {
                time_s: period_s,
                lookahead_s: 0.03,
                gain: 1500.0,
            },
            predict: true,
            predictor: PredictorConfig::default(),
            joint_margin_rad: 0.05,
            speed_fraction: 0.5,
            max_joint_accel: 12.0,
            max_tcp_speed: 0.25,
            servo_deviation_m: 0.02,
            plan_rotation_rad: 0.7,
            shell_distance_m: 0.05,
            approach_speed_m_s: 0.05,
            approach_accel_m_s2: 0.2,
            path_lag_m: 0.005,
            tracker_stale_s: 0.075,
            frozen_samples: 20,
            outlier_speed_m_s: 1.0,
            outlier_speed_rad_s: 10.0,
            max_head_speed_m_s: 0.15,
            max_head_speed_rad_s: 1.2,
            resume_after_s: 0.2,
            robot_stale_periods: 5.0,
            singularity_slow: 0.1,
            singularity_hold: 0.02,
            stop_decel: 4.0,
            head: HeadModel {
                head_from_ellipsoid: Isometry3::identity(),
                radii: Vector3::new(0.075, 0.095, 0.11),
            },
            coil: CoilModel {
                radius: 0.04,
                thickness: 0.03,
            },
            coil_min_distance_m: 0.0,
            coil_contact_tolerance_m: 0.002,
            link_clearance_m: 0.01,
            link_radius_m: 0.045,
            approach_tolerance_m: 0.01,
            approach_zone_m: 0.03,
        }
    }
}
