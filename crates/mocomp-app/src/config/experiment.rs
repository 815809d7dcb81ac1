//! `[experiment]`: the paper's two-robot experiment, and the keys it does not use.

use super::*;

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
pub(crate) fn flatten(prefix: &str, t: &toml::Table, out: &mut Vec<(String, toml::Value)>) {
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

/// The value at a dotted path.
pub(crate) fn lookup<'a>(t: &'a toml::Table, path: &str) -> Option<&'a toml::Value> {
    let mut parts = path.split('.');
    let mut v = t.get(parts.next()?)?;
    for p in parts {
        v = v.as_table()?.get(p)?;
    }
    Some(v)
}

/// Equal as configuration values: `0` and `0.0` are the same number.
pub(crate) fn same_value(a: &toml::Value, b: &toml::Value) -> bool {
    use toml::Value::{Array, Float, Integer};
    match (a, b) {
        (Integer(x), Float(y)) | (Float(y), Integer(x)) => (*x as f64) == *y,
        (Array(x), Array(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(a, b)| same_value(a, b))
        }
        _ => a == b,
    }
}
