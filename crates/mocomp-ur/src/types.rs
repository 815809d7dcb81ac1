//! RTDE data types, values, and the controller's variable table (which names exist, as outputs
//! or inputs, and with which type). The table follows the controller (URCL's `g_type_list`, UR's
//! RTDE guide); clients such as ur_rtde decode with their own copy of it, so a controller (and our
//! simulator) must report exactly these types.

use std::fmt;

/// An RTDE field type (big-endian, no padding).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataType {
    /// `BOOL`, 1 byte.
    Bool,
    /// `UINT8`.
    Uint8,
    /// `UINT32`.
    Uint32,
    /// `UINT64`.
    Uint64,
    /// `INT32`.
    Int32,
    /// `DOUBLE`.
    Double,
    /// `VECTOR3D`: 3 doubles.
    Vector3d,
    /// `VECTOR6D`: 6 doubles.
    Vector6d,
    /// `VECTOR6INT32`.
    Vector6Int32,
    /// `VECTOR6UINT32`.
    Vector6Uint32,
}

impl DataType {
    /// Every type, for tests and tables.
    pub const ALL: [DataType; 10] = [
        DataType::Bool,
        DataType::Uint8,
        DataType::Uint32,
        DataType::Uint64,
        DataType::Int32,
        DataType::Double,
        DataType::Vector3d,
        DataType::Vector6d,
        DataType::Vector6Int32,
        DataType::Vector6Uint32,
    ];

    /// The name on the wire (`"VECTOR6D"`).
    pub fn name(self) -> &'static str {
        match self {
            DataType::Bool => "BOOL",
            DataType::Uint8 => "UINT8",
            DataType::Uint32 => "UINT32",
            DataType::Uint64 => "UINT64",
            DataType::Int32 => "INT32",
            DataType::Double => "DOUBLE",
            DataType::Vector3d => "VECTOR3D",
            DataType::Vector6d => "VECTOR6D",
            DataType::Vector6Int32 => "VECTOR6INT32",
            DataType::Vector6Uint32 => "VECTOR6UINT32",
        }
    }

    /// Parses a wire name.
    pub fn from_name(s: &str) -> Option<DataType> {
        DataType::ALL.into_iter().find(|t| t.name() == s)
    }

    /// Encoded size, bytes.
    pub fn size(self) -> usize {
        match self {
            DataType::Bool | DataType::Uint8 => 1,
            DataType::Uint32 | DataType::Int32 => 4,
            DataType::Uint64 | DataType::Double => 8,
            DataType::Vector3d => 24,
            DataType::Vector6d => 48,
            DataType::Vector6Int32 | DataType::Vector6Uint32 => 24,
        }
    }

    /// The zero value of this type.
    pub fn zero(self) -> Value {
        match self {
            DataType::Bool => Value::Bool(false),
            DataType::Uint8 => Value::Uint8(0),
            DataType::Uint32 => Value::Uint32(0),
            DataType::Uint64 => Value::Uint64(0),
            DataType::Int32 => Value::Int32(0),
            DataType::Double => Value::Double(0.0),
            DataType::Vector3d => Value::Vector3d([0.0; 3]),
            DataType::Vector6d => Value::Vector6d([0.0; 6]),
            DataType::Vector6Int32 => Value::Vector6Int32([0; 6]),
            DataType::Vector6Uint32 => Value::Vector6Uint32([0; 6]),
        }
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One field value. `Copy`, so a recipe's values live in a reused buffer without allocation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// `BOOL`.
    Bool(bool),
    /// `UINT8`.
    Uint8(u8),
    /// `UINT32`.
    Uint32(u32),
    /// `UINT64`.
    Uint64(u64),
    /// `INT32`.
    Int32(i32),
    /// `DOUBLE`.
    Double(f64),
    /// `VECTOR3D`.
    Vector3d([f64; 3]),
    /// `VECTOR6D`.
    Vector6d([f64; 6]),
    /// `VECTOR6INT32`.
    Vector6Int32([i32; 6]),
    /// `VECTOR6UINT32`.
    Vector6Uint32([u32; 6]),
}

impl Value {
    /// The value's type.
    pub fn data_type(&self) -> DataType {
        match self {
            Value::Bool(_) => DataType::Bool,
            Value::Uint8(_) => DataType::Uint8,
            Value::Uint32(_) => DataType::Uint32,
            Value::Uint64(_) => DataType::Uint64,
            Value::Int32(_) => DataType::Int32,
            Value::Double(_) => DataType::Double,
            Value::Vector3d(_) => DataType::Vector3d,
            Value::Vector6d(_) => DataType::Vector6d,
            Value::Vector6Int32(_) => DataType::Vector6Int32,
            Value::Vector6Uint32(_) => DataType::Vector6Uint32,
        }
    }

    /// A scalar as `f64` (integers converted exactly up to 2^53), `None` for vectors.
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            Value::Bool(b) => Some(if b { 1.0 } else { 0.0 }),
            Value::Uint8(x) => Some(f64::from(x)),
            Value::Uint32(x) => Some(f64::from(x)),
            Value::Uint64(x) => Some(x as f64),
            Value::Int32(x) => Some(f64::from(x)),
            Value::Double(x) => Some(x),
            _ => None,
        }
    }

    /// A `VECTOR6D` value.
    pub fn as_vec6(&self) -> Option<[f64; 6]> {
        match *self {
            Value::Vector6d(v) => Some(v),
            _ => None,
        }
    }

    /// Appends the big-endian encoding.
    pub fn encode(&self, out: &mut Vec<u8>) {
        match *self {
            Value::Bool(b) => out.push(u8::from(b)),
            Value::Uint8(x) => out.push(x),
            Value::Uint32(x) => out.extend_from_slice(&x.to_be_bytes()),
            Value::Uint64(x) => out.extend_from_slice(&x.to_be_bytes()),
            Value::Int32(x) => out.extend_from_slice(&x.to_be_bytes()),
            Value::Double(x) => out.extend_from_slice(&x.to_be_bytes()),
            Value::Vector3d(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6d(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6Int32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
            Value::Vector6Uint32(v) => v
                .iter()
                .for_each(|x| out.extend_from_slice(&x.to_be_bytes())),
        }
    }

    /// Decodes one value of type `t` from the front of `b` (which must hold `t.size()` bytes;
    /// the caller checks). A `BOOL` byte other than 0 is true, as on the controller.
    pub(crate) fn decode(t: DataType, b: &[u8]) -> Value {
        fn q(b: &[u8], i: usize) -> [u8; 8] {
            let mut a = [0u8; 8];
            a.copy_from_slice(&b[8 * i..8 * i + 8]);
            a
        }
        fn f(b: &[u8], i: usize) -> f64 {
            f64::from_be_bytes(q(b, i))
        }
        fn w(b: &[u8], i: usize) -> [u8; 4] {
            let mut a = [0u8; 4];
            a.copy_from_slice(&b[4 * i..4 * i + 4]);
            a
        }
        match t {
            DataType::Bool => Value::Bool(b[0] != 0),
            DataType::Uint8 => Value::Uint8(b[0]),
            DataType::Uint32 => Value::Uint32(u32::from_be_bytes(w(b, 0))),
            DataType::Int32 => Value::Int32(i32::from_be_bytes(w(b, 0))),
            DataType::Uint64 => Value::Uint64(u64::from_be_bytes(q(b, 0))),
            DataType::Double => Value::Double(f(b, 0)),
            DataType::Vector3d => Value::Vector3d(std::array::from_fn(|i| f(b, i))),
            DataType::Vector6d => Value::Vector6d(std::array::from_fn(|i| f(b, i))),
            DataType::Vector6Int32 => {
                Value::Vector6Int32(std::array::from_fn(|i| i32::from_be_bytes(w(b, i))))
            }
            DataType::Vector6Uint32 => {
                Value::Vector6Uint32(std::array::from_fn(|i| u32::from_be_bytes(w(b, i))))
            }
        }
    }
}

/// Registers per kind (`input_int_register_0..47`, …).
pub const REGISTERS: u32 = 48;

/// The index in `name` after `prefix`, if it is a decimal number within `range`.
pub(crate) fn indexed(name: &str, prefix: &str, range: std::ops::Range<u32>) -> Option<u32> {
    let rest = name.strip_prefix(prefix)?;
    if rest.is_empty() || rest.len() > 3 || !rest.bytes().all(|c| c.is_ascii_digit()) {
        return None;
    }
    // No leading zeros: the controller knows `register_1`, not `register_01`.
    if rest.len() > 1 && rest.starts_with('0') {
        return None;
    }
    let i: u32 = rest.parse().ok()?;
    range.contains(&i).then_some(i)
}

/// Types of the register variables (inputs, readable as outputs too).
fn input_register_type(name: &str) -> Option<DataType> {
    if indexed(name, "input_int_register_", 0..REGISTERS).is_some() {
        Some(DataType::Int32)
    } else if indexed(name, "input_double_register_", 0..REGISTERS).is_some() {
        Some(DataType::Double)
    } else if name == "input_bit_registers0_to_31" || name == "input_bit_registers32_to_63" {
        Some(DataType::Uint32)
    } else if indexed(name, "input_bit_register_", 64..128).is_some() {
        Some(DataType::Bool)
    } else {
        None
    }
}

/// The type of an output (controller → client) variable, or `None` when the controller would
/// answer `NOT_FOUND`.
pub fn output_type(name: &str) -> Option<DataType> {
    use DataType::*;
    let t = match name {
        "timestamp" => Double,
        "target_q"
        | "target_qd"
        | "target_qdd"
        | "target_current"
        | "target_moment"
        | "actual_q"
        | "actual_qd"
        | "actual_current"
        | "actual_current_window"
        | "actual_current_as_torque"
        | "joint_control_output"
        | "actual_TCP_pose"
        | "actual_TCP_speed"
        | "actual_TCP_force"
        | "target_TCP_pose"
        | "target_TCP_speed"
        | "joint_temperatures"
        | "actual_joint_voltage"
        | "tcp_offset"
        | "ft_raw_wrench"
        | "payload_inertia" => Vector6d,
        "actual_tool_accelerometer"
        | "elbow_position"
        | "elbow_velocity"
        | "payload_cog"
        | "target_gravity" => Vector3d,
        "actual_digital_input_bits"
        | "actual_digital_output_bits"
        | "actual_configurable_digital_input_bits"
        | "actual_configurable_digital_output_bits"
        | "control_step" => Uint64,
        "robot_mode" | "safety_mode" | "safety_status" | "tool_output_voltage" => Int32,
        "joint_mode" => Vector6Int32,
        "runtime_state"
        | "robot_status_bits"
        | "safety_status_bits"
        | "tool_mode"
        | "tool_analog_input_types"
        | "analog_io_types"
        | "script_control_line"
        | "euromap67_input_bits"
        | "euromap67_output_bits"
        | "output_bit_registers0_to_31"
        | "output_bit_registers32_to_63" => Uint32,
        "tool_output_mode" | "tool_digital_output0_mode" | "tool_digital_output1_mode" => Uint8,
        "speed_scaling"
        | "target_speed_fraction"
        | "actual_execution_time"
        | "actual_momentum"
        | "actual_main_voltage"
        | "actual_robot_voltage"
        | "actual_robot_current"
        | "standard_analog_input0"
        | "standard_analog_input1"
        | "standard_analog_output0"
        | "standard_analog_output1"
        | "io_current"
        | "tool_analog_input0"
        | "tool_analog_input1"
        | "tool_output_current"
        | "tool_temperature"
        | "tool_force_scalar"
        | "euromap67_24V_voltage"
        | "euromap67_24V_current"
        | "payload"
        | "joint_position_deviation_ratio" => Double,
        _ => {
            if indexed(name, "output_int_register_", 0..REGISTERS).is_some() {
                Int32
            } else if indexed(name, "output_double_register_", 0..REGISTERS).is_some() {
                Double
            } else if indexed(name, "output_bit_register_", 64..128).is_some() {
                Bool
            } else {
                return input_register_type(name);
            }
        }
    };
    Some(t)
}

/// The type of an input (client → controller) variable, or `None` when the controller would
/// answer `NOT_FOUND`.
pub fn input_type(name: &str) -> Option<DataType> {
    use DataType::*;
    let t = match name {
        "speed_slider_mask" => Uint32,
        "speed_slider_fraction" | "standard_analog_output_0" | "standard_analog_output_1" => Double,
        "standard_digital_output_mask"
        | "standard_digital_output"
        | "configurable_digital_output_mask"
        | "configurable_digital_output"
        | "tool_digital_output_mask"
        | "tool_digital_output"
        | "standard_analog_output_mask"
        | "standard_analog_output_type" => Uint8,
        "external_force_torque" => Vector6d,
        _ => return input_register_type(name),
    };
    Some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_has_the_types_ur_rtde_decodes_with() {
        // ur_rtde's own table (robot_state.cpp) for its default receive variables.
        assert_eq!(output_type("actual_q"), Some(DataType::Vector6d));
        assert_eq!(output_type("joint_mode"), Some(DataType::Vector6Int32));
        assert_eq!(output_type("robot_status_bits"), Some(DataType::Uint32));
        assert_eq!(output_type("safety_mode"), Some(DataType::Int32));
        assert_eq!(
            output_type("actual_digital_input_bits"),
            Some(DataType::Uint64)
        );
        assert_eq!(output_type("payload_cog"), Some(DataType::Vector3d));
        assert_eq!(output_type("output_int_register_47"), Some(DataType::Int32));
        assert_eq!(
            output_type("input_double_register_3"),
            Some(DataType::Double)
        );
        assert_eq!(output_type("output_bit_register_64"), Some(DataType::Bool));
        assert_eq!(output_type("output_int_register_48"), None);
        assert_eq!(output_type("output_int_register_01"), None);
        assert_eq!(output_type("output_bit_register_63"), None);
        assert_eq!(output_type("no_such_var"), None);
        assert_eq!(input_type("input_int_register_24"), Some(DataType::Int32));
        assert_eq!(input_type("speed_slider_mask"), Some(DataType::Uint32));
        assert_eq!(
            input_type("external_force_torque"),
            Some(DataType::Vector6d)
        );
        assert_eq!(input_type("actual_q"), None, "outputs are not inputs");
    }

    #[test]
    fn values_round_trip_and_sizes_match() {
        let vals = [
            Value::Bool(true),
            Value::Uint8(200),
            Value::Uint32(0xdead_beef),
            Value::Uint64(u64::MAX - 3),
            Value::Int32(-7),
            Value::Double(-1.5e-300),
            Value::Vector3d([1.0, -2.0, 3.5]),
            Value::Vector6d([0.1, 0.2, 0.3, 0.4, 0.5, -0.6]),
            Value::Vector6Int32([253, -1, 0, 7, 8, i32::MIN]),
            Value::Vector6Uint32([1, 2, 3, 4, 5, u32::MAX]),
        ];
        for v in vals {
            let mut b = Vec::new();
            v.encode(&mut b);
            assert_eq!(b.len(), v.data_type().size(), "{v:?}");
            assert_eq!(Value::decode(v.data_type(), &b), v);
            assert_eq!(
                DataType::from_name(v.data_type().name()),
                Some(v.data_type())
            );
        }
        // Golden bytes: big-endian.
        let mut b = Vec::new();
        Value::Double(1.0).encode(&mut b);
        Value::Int32(-2).encode(&mut b);
        assert_eq!(b, [0x3f, 0xf0, 0, 0, 0, 0, 0, 0, 0xff, 0xff, 0xff, 0xfe]);
    }
}
