//! `[calibrate]`: `calibrate collect` and the experiment's calibrations.

use super::*;

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
