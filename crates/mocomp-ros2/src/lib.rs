//! mocomp in a ROS 2 system, without a ROS installation.
//!
//! - [`msg`]: the ROS 2 messages mocomp speaks (`sensor_msgs/JointState`, `tf2_msgs/TFMessage`,
//!   `geometry_msgs/PoseStamped`, `diagnostic_msgs/DiagnosticArray`, `std_srvs/Trigger`), as serde
//!   structs in ROS 2's field order, their CDR (the wire format of DDS and of MCAP recordings) and
//!   their `.msg` definitions.
//! - [`convert`]: poses and times into those messages. Pure.
//! - [`cycle`]: what a cycle and the status become in ROS 2 (the node's and a recording's
//!   messages, built in one place). Pure.
//! - [`node`]: the node, on its own thread: it publishes what the loop sends it, serves hold and
//!   resume, and takes head poses from a topic.
//!
//! ROS 2 on the wire is DDS: topic `/joint_states` is the DDS topic `rt/joint_states` of type
//! `sensor_msgs::msg::dds_::JointState_`; `ros2-client` (pure Rust, over RustDDS) does that
//! mapping, so any ROS 2 node (Cyclone DDS, Fast DDS) sees mocomp as one of its own.
//!
//! **Limits.** No ROS installation and no loop: messages, the node and its DDS participant; the
//! application decides what to publish and what a service call does.

pub mod convert;
pub mod cycle;
pub mod msg;
pub mod node;

pub use cycle::{CycleMessages, Frames, Snapshot, Status};
pub use node::{Out, Ros2Bridge, Ros2Config, Ros2Error};
