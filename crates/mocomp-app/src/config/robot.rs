//! `[robot]` and `[servo]`: the arm and how it is servoed.

use super::*;

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

impl ServoSection {
    /// The servo parameters at a controller period (the robot model's).
    pub fn params(&self, period_s: f64) -> ServoParams {
        ServoParams {
            time_s: period_s,
            lookahead_s: self.lookahead_s,
            gain: self.gain,
        }
    }

    /// servoj's ranges, by the robot interface's own rule (the one every servo command is held
    /// to), so the file and the command cannot disagree; the error names the key.
    pub(super) fn check(&self) -> Result<(), AppError> {
        // Any period the interface accepts: the section has none of its own.
        let at_500_hz = self.params(0.002);
        at_500_hz.validate().map_err(|e| match e {
            mocomp_robot::RobotError::OutOfRange {
                field,
                value,
                min,
                max,
            } => AppError::Config(format!(
                "{} = {value}: must be in [{min}, {max}]",
                field.replace("servo ", "servo.")
            )),
            other => AppError::Config(format!("servo: {other}")),
        })
    }
}

impl RobotSection {
    /// The controller's address is an IP address.
    pub(super) fn check(&self) -> Result<(), AppError> {
        self.host
            .parse::<IpAddr>()
            .map_err(|e| AppError::Config(format!("robot.host {:?}: {e}", self.host)))?;
        Ok(())
    }
}
