//! The ROS 2 messages mocomp speaks: serde structs whose fields are in the order of the ROS 2
//! definitions (CDR has no field names: the order is the format), their DDS type names and
//! their `.msg` definitions (MCAP's `ros2msg` schemas). CDR is little endian XCDR1 with its
//! 4-byte encapsulation header, as ROS 2 sends it.

use serde::{Deserialize, Serialize};

/// A message's ROS 2 name: package and type (`sensor_msgs`, `JointState`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TypeName {
    /// The package.
    pub package: &'static str,
    /// The type.
    pub name: &'static str,
}

impl TypeName {
    /// `package/msg/Name`, as ROS 2 tools and MCAP name it.
    pub fn ros(&self) -> String {
        format!("{}/msg/{}", self.package, self.name)
    }

    /// The DDS type name: `package::msg::dds_::Name_`.
    pub fn dds(&self) -> String {
        format!("{}::msg::dds_::{}_", self.package, self.name)
    }
}

/// A ROS 2 message mocomp sends or takes.
pub trait RosMessage: Serialize + for<'de> Deserialize<'de> + ros2_client::Message {
    /// Its name.
    const TYPE: TypeName;
    /// Its `.msg` definition with every type it uses appended (MCAP's `ros2msg` encoding).
    const DEFINITION: &'static str;
}

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, below 10⁹.
    pub nanosec: u32,
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// In which frame.
    pub frame_id: String,
}

/// `sensor_msgs/JointState`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp of the robot's state.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// Positions, rad.
    pub position: Vec<f64>,
    /// Velocities, rad/s.
    pub velocity: Vec<f64>,
    /// Efforts (empty: not given).
    pub effort: Vec<f64>,
}

/// `geometry_msgs/Point`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// m.
    pub x: f64,
    /// m.
    pub y: f64,
    /// m.
    pub z: f64,
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Self {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position, m.
    pub position: Point,
    /// Orientation.
    pub orientation: Quaternion,
}

/// `geometry_msgs/PoseStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The pose in that frame.
    pub pose: Pose,
}

/// `geometry_msgs/Transform`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// m.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`: `header.frame_id` from `child_frame_id`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Stamp and parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// parent_from_child.
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// The transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `diagnostic_msgs/KeyValue`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// 0 OK, 1 WARN, 2 ERROR, 3 STALE.
    pub level: u8,
    /// What is described.
    pub name: String,
    /// In words.
    pub message: String,
    /// The hardware.
    pub hardware_id: String,
    /// Figures.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/DiagnosticArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// The statuses.
    pub status: Vec<DiagnosticStatus>,
}

/// `std_srvs/Trigger` request. Empty in ROS 2's `.srv`; its IDL (and so the wire) has one byte,
/// as every empty ROS 2 structure.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerRequest {
    /// Always 0.
    pub structure_needs_at_least_one_member: u8,
}

/// `std_srvs/Trigger` response.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerResponse {
    /// Whether it was done.
    pub success: bool,
    /// Why not, or what was done.
    pub message: String,
}

macro_rules! ros_message {
    ($t:ty, $package:literal, $name:literal, $definition:expr) => {
        impl ros2_client::Message for $t {}
        impl RosMessage for $t {
            const TYPE: TypeName = TypeName {
                package: $package,
                name: $name,
            };
            const DEFINITION: &'static str = $definition;
        }
    };
}

macro_rules! def {
    ($($part:expr),* $(,)?) => { concat!($($part),*) };
}

ros_message!(
    JointState,
    "sensor_msgs",
    "JointState",
    def!(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
        "================================================================================\n",
        "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n",
        "================================================================================\n",
        "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
    )
);
ros_message!(
    PoseStamped,
    "geometry_msgs",
    "PoseStamped",
    def!(
        "std_msgs/Header header\ngeometry_msgs/Pose pose\n",
        "================================================================================\n",
        "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n",
        "================================================================================\n",
        "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    )
);
ros_message!(
    TfMessage,
    "tf2_msgs",
    "TFMessage",
    def!(
        "geometry_msgs/TransformStamped[] transforms\n",
        "================================================================================\n",
        "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
        "================================================================================\n",
        "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n",
        "================================================================================\n",
        "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
        "================================================================================\n",
        "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    )
);
ros_message!(
    DiagnosticArray,
    "diagnostic_msgs",
    "DiagnosticArray",
    def!(
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n",
        "================================================================================\n",
        "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n",
        "================================================================================\n",
        "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
        "================================================================================\n",
        "MSG: diagnostic_msgs/DiagnosticStatus\nbyte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\ndiagnostic_msgs/KeyValue[] values\n",
        "================================================================================\n",
        "MSG: diagnostic_msgs/KeyValue\nstring key\nstring value\n",
    )
);
ros_message!(TriggerRequest, "std_srvs", "Trigger_Request", "\n");
ros_message!(
    TriggerResponse,
    "std_srvs",
    "Trigger_Response",
    "bool success\nstring message\n"
);

/// Why a message could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum CdrError {
    /// Too short for the encapsulation header, or not little-endian CDR.
    #[error("not little-endian CDR: {0}")]
    Encapsulation(String),
    /// The body does not decode as this type.
    #[error("{type_name}: {source}")]
    Body {
        /// The type.
        type_name: String,
        /// Why.
        #[source]
        source: cdr_encoding::Error,
    },
}

/// CDR little endian's encapsulation header (XCDR1, `CDR_LE`).
pub const CDR_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// The message as ROS 2 sends it: the encapsulation header, then its little-endian CDR.
pub fn to_cdr<M: RosMessage>(m: &M) -> Result<Vec<u8>, CdrError> {
    let body =
        cdr_encoding::to_vec::<M, byteorder::LittleEndian>(m).map_err(|source| CdrError::Body {
            type_name: M::TYPE.ros(),
            source,
        })?;
    let mut out = Vec::with_capacity(4 + body.len());
    out.extend_from_slice(&CDR_LE);
    out.extend_from_slice(&body);
    Ok(out)
}

/// A message from its CDR (with its encapsulation header; little endian only).
pub fn from_cdr<M: RosMessage>(bytes: &[u8]) -> Result<M, CdrError> {
    let Some((head, body)) = bytes.split_first_chunk::<4>() else {
        return Err(CdrError::Encapsulation(format!(
            "{} bytes, less than the 4-byte header",
            bytes.len()
        )));
    };
    if head[..2] != CDR_LE[..2] {
        return Err(CdrError::Encapsulation(format!(
            "encapsulation {:02x} {:02x}",
            head[0], head[1]
        )));
    }
    cdr_encoding::from_bytes::<M, byteorder::LittleEndian>(body)
        .map(|(m, _)| m)
        .map_err(|source| CdrError::Body {
            type_name: M::TYPE.ros(),
            source,
        })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn a_pose_stamped_is_the_cdr_ros_2_sends_byte_for_byte() {
        let m = PoseStamped {
            header: Header {
                stamp: Time {
                    sec: 1_700_000_000,
                    nanosec: 250_000_000,
                },
                frame_id: "base".into(),
            },
            pose: Pose {
                position: Point {
                    x: 0.5,
                    y: -1.0,
                    z: 2.0,
                },
                orientation: Quaternion::default(),
            },
        };
        // Encapsulation, then: sec, nanosec, the string's length with its NUL and its bytes,
        // padding to the doubles' 8-byte alignment (counted from after the encapsulation),
        // seven doubles.
        let mut want = vec![0x00, 0x01, 0x00, 0x00];
        want.extend(1_700_000_000i32.to_le_bytes());
        want.extend(250_000_000u32.to_le_bytes());
        want.extend(5u32.to_le_bytes());
        want.extend(b"base\0");
        want.extend([0u8; 7]);
        for v in [0.5f64, -1.0, 2.0, 0.0, 0.0, 0.0, 1.0] {
            want.extend(v.to_le_bytes());
        }
        let got = to_cdr(&m).unwrap();
        assert_eq!(got, want);
        assert_eq!(from_cdr::<PoseStamped>(&got).unwrap(), m);
    }

    #[test]
    fn every_message_reads_back_and_bad_bytes_are_refused_not_panicked_on() {
        let js = JointState {
            header: Header::default(),
            name: vec!["a".into(), "bb".into()],
            position: vec![1.0, 2.0],
            velocity: vec![0.5],
            effort: vec![],
        };
        assert_eq!(from_cdr::<JointState>(&to_cdr(&js).unwrap()).unwrap(), js);
        let d = DiagnosticArray {
            header: Header::default(),
            status: vec![DiagnosticStatus {
                level: 2,
                name: "n".into(),
                message: "m".into(),
                hardware_id: "h".into(),
                values: vec![KeyValue {
                    key: "k".into(),
                    value: "v".into(),
                }],
            }],
        };
        assert_eq!(
            from_cdr::<DiagnosticArray>(&to_cdr(&d).unwrap()).unwrap(),
            d
        );
        let tf = TfMessage {
            transforms: vec![TransformStamped::default(); 3],
        };
        assert_eq!(from_cdr::<TfMessage>(&to_cdr(&tf).unwrap()).unwrap(), tf);
        let bytes = to_cdr(&js).unwrap();
        // Every truncation is an error, never a panic.
        for n in 0..bytes.len() {
            assert!(from_cdr::<JointState>(&bytes[..n]).is_err(), "{n} bytes");
        }
        assert!(matches!(
            from_cdr::<JointState>(&[0x00, 0x00, 0, 0]),
            Err(CdrError::Encapsulation(_))
        ));
        assert_eq!(
            JointState::TYPE.dds(),
            "sensor_msgs::msg::dds_::JointState_"
        );
        assert_eq!(TfMessage::TYPE.ros(), "tf2_msgs/msg/TFMessage");
    }
}
