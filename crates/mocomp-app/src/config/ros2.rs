//! `[ros2]`: mocomp as a ROS 2 node.

use super::*;

/// `[ros2]`: `mocomp run` as a ROS 2 node (no ROS installation needed): it publishes
/// `/joint_states`, `/tf`, `/mocomp/coil_pose`, `/mocomp/head_pose` and `/diagnostics`, and serves
/// `/mocomp/hold` and `/mocomp/resume` (`std_srvs/Trigger`). `tracker.source = "ros2"` takes the
/// head's poses from a `geometry_msgs/PoseStamped` topic with or without it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Section {
    /// Publish and serve (or: `mocomp run --ros2`).
    pub enabled: bool,
    /// The DDS domain (default: `ROS_DOMAIN_ID`, else 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub domain_id: Option<u16>,
    /// The node's name.
    pub node_name: String,
    /// Joint states, TF and poses at most this often, Hz (0: every cycle, the robot's rate).
    pub publish_hz: f64,
    /// The head's poses for `tracker.source = "ros2"`: a `geometry_msgs/PoseStamped` topic, the
    /// head marker in the tracker's frame, stamped at acquisition.
    pub head_topic: String,
    /// How services map onto DDS: "enhanced" (Fast DDS, ROS 2's default) or "cyclone"
    /// (`rmw_cyclonedds_cpp`), as the other nodes' DDS.
    pub service_mapping: mocomp_ros2::node::ServiceMappingName,
    /// The frame names.
    pub frames: mocomp_ros2::Frames,
}

impl Default for Ros2Section {
    fn default() -> Self {
        Self {
            enabled: false,
            domain_id: None,
            node_name: "mocomp".into(),
            publish_hz: 0.0,
            head_topic: "/mocomp/tracker/head".into(),
            service_mapping: mocomp_ros2::node::ServiceMappingName::Enhanced,
            frames: mocomp_ros2::Frames::default(),
        }
    }
}

impl Ros2Section {
    /// The node's settings: the domain from the section, else `ROS_DOMAIN_ID` (which must then
    /// be a number below 233, DDS's range for it), else 0.
    pub fn node_config(&self, head: bool) -> Result<mocomp_ros2::Ros2Config, AppError> {
        let domain_id = match (self.domain_id, std::env::var("ROS_DOMAIN_ID")) {
            (Some(d), _) => d,
            (None, Ok(v)) if !v.trim().is_empty() => v
                .trim()
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or_else(|| {
                    AppError::Config(format!("ROS_DOMAIN_ID={v:?}: must be a number 0 to 232"))
                })?,
            _ => 0,
        };
        Ok(mocomp_ros2::Ros2Config {
            domain_id,
            node_name: self.node_name.clone(),
            frames: self.frames.clone(),
            head_topic: head.then(|| self.head_topic.clone()),
            service_mapping: self.service_mapping,
            ..mocomp_ros2::Ros2Config::default()
        })
    }
}

impl Ros2Section {
    /// Its rate and the head's topic name.
    pub(super) fn check(&self) -> Result<(), AppError> {
        Check::range("ros2.publish_hz", self.publish_hz, 0.0, 1000.0, false)?;
        if !self.head_topic.starts_with('/') {
            return Err(AppError::Config(format!(
                "ros2.head_topic {:?}: a topic name starts with /",
                self.head_topic
            )));
        }
        Ok(())
    }
}
