//! `[calibration]` and `[goal]`: the frames a real cell measures, and the simulated world's.

use super::*;

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
