//! What one cycle and the once-a-second status become in ROS 2: the messages the node
//! publishes and a recording stores, built in one place. Pure.

use crate::convert;
use crate::msg::{
    DiagnosticArray, DiagnosticStatus, Header, JointState, KeyValue, PoseStamped, TfMessage,
    TransformStamped,
};
use mocomp_geom::nalgebra::Isometry3;

/// The frame names (`tf` and the headers).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Frames {
    /// The robot's base. [`base`, as the UR ROS 2 driver]
    pub base: String,
    /// Its flange. [`tool0`]
    pub flange: String,
    /// The tracker. [`tracker`]
    pub tracker: String,
    /// The head marker. [`head`]
    pub head: String,
    /// The coil's goal on the head. [`coil_goal`]
    pub coil_goal: String,
}

impl Default for Frames {
    fn default() -> Self {
        Self {
            base: "base".into(),
            flange: "tool0".into(),
            tracker: "tracker".into(),
            head: "head".into(),
            coil_goal: "coil_goal".into(),
        }
    }
}

/// One cycle, as the node publishes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Snapshot {
    /// When the robot's state was received, s since the Unix epoch.
    pub stamp_unix_s: f64,
    /// Measured joints, rad.
    pub q: [f64; 6],
    /// Measured joint speeds, rad/s.
    pub qd: [f64; 6],
    /// base_from_flange (FK of the measured joints).
    pub base_from_flange: Isometry3<f64>,
    /// base_from_coil, measured.
    pub base_from_coil: Isometry3<f64>,
    /// The calibration's base_from_tracker.
    pub base_from_tracker: Isometry3<f64>,
    /// The head estimated for the cycle's time, when known.
    pub tracker_from_head: Option<Isometry3<f64>>,
    /// The goal, head_from_coil.
    pub head_from_coil_goal: Isometry3<f64>,
}

/// The loop's status, once a second (`/diagnostics`).
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    /// s since the Unix epoch.
    pub stamp_unix_s: f64,
    /// 0 OK (tracking), 1 WARN (approaching, retreating, held), 2 ERROR (faulted).
    pub level: u8,
    /// The mode and its reason, in words.
    pub message: String,
    /// Figures: key, value.
    pub values: Vec<(String, String)>,
}

/// One cycle's messages.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleMessages {
    /// `/joint_states`.
    pub joints: JointState,
    /// `/tf`: base → flange, base → tracker, tracker → head (when known), head → coil goal.
    pub tf: TfMessage,
    /// `/mocomp/coil_pose`, in the base frame.
    pub coil: PoseStamped,
    /// `/mocomp/head_pose`, in the base frame (when the head is known).
    pub head: Option<PoseStamped>,
}

fn header(stamp_unix_s: f64, frame: &str) -> Header {
    Header {
        stamp: convert::time(stamp_unix_s),
        frame_id: frame.to_string(),
    }
}

impl CycleMessages {
    /// The messages of `s`, with these joint and frame names.
    pub fn of(s: &Snapshot, joint_names: &[String; 6], f: &Frames) -> Self {
        let stamp = s.stamp_unix_s;
        let tf_of = |parent: &str, child: &str, iso: &Isometry3<f64>| TransformStamped {
            header: header(stamp, parent),
            child_frame_id: child.to_string(),
            transform: convert::transform(iso),
        };
        let mut transforms = vec![
            tf_of(&f.base, &f.flange, &s.base_from_flange),
            tf_of(&f.base, &f.tracker, &s.base_from_tracker),
        ];
        if let Some(h) = &s.tracker_from_head {
            transforms.push(tf_of(&f.tracker, &f.head, h));
        }
        transforms.push(tf_of(&f.head, &f.coil_goal, &s.head_from_coil_goal));
        Self {
            joints: JointState {
                header: header(stamp, ""),
                name: joint_names.to_vec(),
                position: s.q.to_vec(),
                velocity: s.qd.to_vec(),
                effort: Vec::new(),
            },
            tf: TfMessage { transforms },
            coil: PoseStamped {
                header: header(stamp, &f.base),
                pose: convert::pose(&s.base_from_coil),
            },
            head: s.tracker_from_head.map(|h| PoseStamped {
                header: header(stamp, &f.base),
                pose: convert::pose(&(s.base_from_tracker * h)),
            }),
        }
    }
}

impl Status {
    /// `/diagnostics`: one status named after the node.
    pub fn message(&self, node_name: &str) -> DiagnosticArray {
        DiagnosticArray {
            header: header(self.stamp_unix_s, ""),
            status: vec![DiagnosticStatus {
                level: self.level,
                name: format!("{node_name}: compensation loop"),
                message: self.message.clone(),
                hardware_id: node_name.to_string(),
                values: self
                    .values
                    .iter()
                    .map(|(k, v)| KeyValue {
                        key: k.clone(),
                        value: v.clone(),
                    })
                    .collect(),
            }],
        }
    }
}
