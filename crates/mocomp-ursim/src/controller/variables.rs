//! The controller's variables: the RTDE input slots and output variables it serves, by name,
//! and the register store behind them.

use super::*;

pub(super) const NREG: usize = REGISTERS as usize;

/// Where an input variable lands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum InputSlot {
    /// `input_int_register_N`.
    Int(usize),
    /// `input_double_register_N`.
    Double(usize),
    /// `input_bit_registers0_to_31`.
    BitsLow,
    /// `input_bit_registers32_to_63`.
    BitsHigh,
    /// `input_bit_register_N` (64..127).
    Bit(usize),
    /// `speed_slider_mask`.
    SliderMask,
    /// `speed_slider_fraction`.
    SliderFraction,
    /// `*_digital_output_mask` of a bank.
    DigitalMask(Bank),
    /// `*_digital_output` of a bank.
    Digital(Bank),
    /// `standard_analog_output_mask`.
    AnalogMask,
    /// `standard_analog_output_0` / `_1`.
    Analog(usize),
    /// An input the simulator takes and has no use for (`standard_analog_output_type`,
    /// `external_force_torque`).
    Ignored(u8),
}

impl InputSlot {
    /// Resolves an input name; `None` when the controller would answer `NOT_FOUND`.
    pub fn resolve(name: &str) -> Option<(InputSlot, DataType)> {
        let t = input_type(name)?;
        let idx = |p: &str| name.strip_prefix(p).and_then(|r| r.parse::<usize>().ok());
        let slot = if let Some(i) = idx("input_int_register_") {
            InputSlot::Int(i)
        } else if let Some(i) = idx("input_double_register_") {
            InputSlot::Double(i)
        } else if let Some(i) = idx("input_bit_register_") {
            InputSlot::Bit(i)
        } else {
            match name {
                "input_bit_registers0_to_31" => InputSlot::BitsLow,
                "input_bit_registers32_to_63" => InputSlot::BitsHigh,
                "speed_slider_mask" => InputSlot::SliderMask,
                "speed_slider_fraction" => InputSlot::SliderFraction,
                "standard_digital_output_mask" => InputSlot::DigitalMask(Bank::Standard),
                "standard_digital_output" => InputSlot::Digital(Bank::Standard),
                "configurable_digital_output_mask" => InputSlot::DigitalMask(Bank::Configurable),
                "configurable_digital_output" => InputSlot::Digital(Bank::Configurable),
                "tool_digital_output_mask" => InputSlot::DigitalMask(Bank::Tool),
                "tool_digital_output" => InputSlot::Digital(Bank::Tool),
                "standard_analog_output_mask" => InputSlot::AnalogMask,
                "standard_analog_output_0" => InputSlot::Analog(0),
                "standard_analog_output_1" => InputSlot::Analog(1),
                other => InputSlot::Ignored(other.len() as u8),
            }
        };
        Some((slot, t))
    }
}

/// An output variable, resolved once at setup.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OutputVar {
    /// `timestamp`.
    Timestamp,
    /// `target_q` / `actual_q`.
    Q,
    /// `target_qd` / `actual_qd`.
    Qd,
    /// `target_qdd`.
    Qdd,
    /// `actual_TCP_pose` / `target_TCP_pose`.
    TcpPose,
    /// `actual_TCP_speed` / `target_TCP_speed`.
    TcpSpeed,
    /// `actual_TCP_force`: the wrench on the tool, base frame.
    TcpForce,
    /// `robot_mode`.
    RobotMode,
    /// `joint_mode`.
    JointMode,
    /// `safety_mode` / `safety_status`.
    SafetyMode,
    /// `runtime_state`.
    RuntimeState,
    /// `robot_status_bits`.
    RobotStatusBits,
    /// `safety_status_bits`.
    SafetyStatusBits,
    /// `speed_scaling`.
    SpeedScaling,
    /// `target_speed_fraction`.
    SpeedFraction,
    /// `joint_temperatures`.
    Temperatures,
    /// `actual_main_voltage` / `actual_robot_voltage`.
    Voltage,
    /// `actual_joint_voltage`.
    JointVoltage,
    /// `actual_execution_time`.
    ExecutionTime,
    /// `target_gravity` / `actual_tool_accelerometer`.
    Gravity,
    /// `elbow_position`.
    ElbowPosition,
    /// `output_int_register_N`.
    OutInt(usize),
    /// `output_double_register_N`.
    OutDouble(usize),
    /// `input_int_register_N` read back.
    InInt(usize),
    /// `input_double_register_N` read back.
    InDouble(usize),
    /// `output_bit_registers0_to_31` and `32_to_63`.
    OutBits(bool),
    /// `input_bit_registers0_to_31` and `32_to_63`.
    InBits(bool),
    /// `actual_digital_output_bits`.
    DigitalOut,
    /// `actual_digital_input_bits`.
    DigitalIn,
    /// `actual_configurable_digital_output_bits`.
    ConfigurableOut,
    /// `actual_configurable_digital_input_bits`.
    ConfigurableIn,
    /// `standard_analog_output0` / `1`.
    AnalogOut(usize),
    /// Anything else the controller knows: reported as zero of its type.
    Zero(DataType),
}

impl OutputVar {
    /// Resolves an output name; `None` when the controller would answer `NOT_FOUND`.
    pub fn resolve(name: &str) -> Option<(OutputVar, DataType)> {
        let t = output_type(name)?;
        let idx = |p: &str| name.strip_prefix(p).and_then(|r| r.parse::<usize>().ok());
        let v = match name {
            "timestamp" => OutputVar::Timestamp,
            "target_q" | "actual_q" => OutputVar::Q,
            "target_qd" | "actual_qd" => OutputVar::Qd,
            "target_qdd" => OutputVar::Qdd,
            "actual_TCP_pose" | "target_TCP_pose" => OutputVar::TcpPose,
            "actual_TCP_speed" | "target_TCP_speed" => OutputVar::TcpSpeed,
            "actual_TCP_force" => OutputVar::TcpForce,
            "robot_mode" => OutputVar::RobotMode,
            "joint_mode" => OutputVar::JointMode,
            "safety_mode" | "safety_status" => OutputVar::SafetyMode,
            "runtime_state" => OutputVar::RuntimeState,
            "robot_status_bits" => OutputVar::RobotStatusBits,
            "safety_status_bits" => OutputVar::SafetyStatusBits,
            "speed_scaling" => OutputVar::SpeedScaling,
            "target_speed_fraction" => OutputVar::SpeedFraction,
            "joint_temperatures" => OutputVar::Temperatures,
            "actual_main_voltage" | "actual_robot_voltage" => OutputVar::Voltage,
            "actual_joint_voltage" => OutputVar::JointVoltage,
            "actual_execution_time" => OutputVar::ExecutionTime,
            "target_gravity" | "actual_tool_accelerometer" => OutputVar::Gravity,
            "elbow_position" => OutputVar::ElbowPosition,
            "output_bit_registers0_to_31" => OutputVar::OutBits(false),
            "output_bit_registers32_to_63" => OutputVar::OutBits(true),
            "input_bit_registers0_to_31" => OutputVar::InBits(false),
            "input_bit_registers32_to_63" => OutputVar::InBits(true),
            "actual_digital_output_bits" => OutputVar::DigitalOut,
            "actual_digital_input_bits" => OutputVar::DigitalIn,
            "actual_configurable_digital_output_bits" => OutputVar::ConfigurableOut,
            "actual_configurable_digital_input_bits" => OutputVar::ConfigurableIn,
            "standard_analog_output0" => OutputVar::AnalogOut(0),
            "standard_analog_output1" => OutputVar::AnalogOut(1),
            _ => {
                if let Some(i) = idx("output_int_register_") {
                    OutputVar::OutInt(i)
                } else if let Some(i) = idx("output_double_register_") {
                    OutputVar::OutDouble(i)
                } else if let Some(i) = idx("input_int_register_") {
                    OutputVar::InInt(i)
                } else if let Some(i) = idx("input_double_register_") {
                    OutputVar::InDouble(i)
                } else {
                    OutputVar::Zero(t)
                }
            }
        };
        Some((v, t))
    }
}

/// The register store.
#[derive(Debug, Clone)]
pub(super) struct Registers {
    pub(super) in_int: [i32; NREG],
    pub(super) in_double: [f64; NREG],
    pub(super) in_bits: [u32; 2],
    pub(super) in_bit_hi: [bool; 64],
    pub(super) out_int: [i32; NREG],
    pub(super) out_double: [f64; NREG],
    pub(super) out_bits: [u32; 2],
    pub(super) in_int_updated_s: [f64; NREG],
}

impl Default for Registers {
    fn default() -> Self {
        Self {
            in_int: [0; NREG],
            in_double: [0.0; NREG],
            in_bits: [0; 2],
            in_bit_hi: [false; 64],
            out_int: [0; NREG],
            out_double: [0.0; NREG],
            out_bits: [0; 2],
            in_int_updated_s: [f64::NEG_INFINITY; NREG],
        }
    }
}

impl Controller {
    /// Output register value (for tests).
    pub fn output_int(&self, i: usize) -> i32 {
        self.regs.out_int.get(i).copied().unwrap_or(0)
    }

    /// Input register value (for tests).
    pub fn input_int(&self, i: usize) -> i32 {
        self.regs.in_int.get(i).copied().unwrap_or(0)
    }

    // ---------------------------------------------------------------- inputs and programs

    /// Applies one input value (from an RTDE data package).
    pub fn apply_input(&mut self, slot: InputSlot, v: Value) {
        match (slot, v) {
            (InputSlot::Int(i), Value::Int32(x)) if i < NREG => {
                self.regs.in_int[i] = x;
                self.regs.in_int_updated_s[i] = self.time_s;
            }
            (InputSlot::Double(i), Value::Double(x)) if i < NREG => self.regs.in_double[i] = x,
            (InputSlot::BitsLow, Value::Uint32(x)) => self.regs.in_bits[0] = x,
            (InputSlot::BitsHigh, Value::Uint32(x)) => self.regs.in_bits[1] = x,
            (InputSlot::Bit(i), Value::Bool(b)) if (64..128).contains(&i) => {
                self.regs.in_bit_hi[i - 64] = b;
            }
            (InputSlot::SliderMask, Value::Uint32(x)) => self.slider_mask = x,
            (InputSlot::SliderFraction, Value::Double(x)) if x.is_finite() => self.slider = x,
            (InputSlot::DigitalMask(b), Value::Uint8(m)) => self.io.take_mask(b, m),
            (InputSlot::Digital(b), Value::Uint8(v)) => self.io.take_value(b, v),
            (InputSlot::AnalogMask, Value::Uint8(m)) => self.io.take_analog_mask(m),
            (InputSlot::Analog(ch), Value::Double(x)) => self.io.take_analog(ch, x),
            _ => {}
        }
    }

    /// Ends a data package: the I/O it set takes effect together (a mask and its values may
    /// come in either order).
    pub fn finish_inputs(&mut self) {
        self.io.finish_package();
    }

    pub(super) fn read_q(&self, base: usize) -> [f64; 6] {
        std::array::from_fn(|j| self.regs.in_double[(base + j).min(NREG - 1)])
    }

    // ---------------------------------------------------------------- outputs

    pub(super) fn safety_bits(&self) -> u32 {
        match self.safety_mode {
            SafetyMode::Normal => 1,
            SafetyMode::Reduced => 1 << 1,
            SafetyMode::ProtectiveStop => 1 << 2,
            SafetyMode::Recovery => 1 << 3,
            SafetyMode::SafeguardStop => 1 << 4,
            SafetyMode::SystemEmergencyStop => (1 << 5) | (1 << 7),
            SafetyMode::RobotEmergencyStop => (1 << 6) | (1 << 7),
            SafetyMode::Violation => 1 << 8,
            SafetyMode::Fault => 1 << 9,
            _ => 1 << 10,
        }
    }

    /// The value of an output variable now.
    pub fn output(&self, v: OutputVar) -> Value {
        match v {
            OutputVar::Timestamp => Value::Double(self.time_s),
            OutputVar::Q => Value::Vector6d(self.q),
            OutputVar::Qd => Value::Vector6d(self.qd),
            OutputVar::Qdd => Value::Vector6d(self.qdd),
            OutputVar::TcpPose => Value::Vector6d(ur_pose_from_iso(&self.arm.fk(&self.q))),
            OutputVar::TcpForce => Value::Vector6d(self.tcp_force()),
            OutputVar::TcpSpeed => {
                let s = self.arm.jacobian(&self.q) * Vector6::from_column_slice(&self.qd);
                Value::Vector6d(std::array::from_fn(|i| s[i]))
            }
            OutputVar::RobotMode => Value::Int32(self.robot_mode.code()),
            OutputVar::JointMode => Value::Vector6Int32(
                [match self.robot_mode {
                    RobotMode::Running => 253,
                    RobotMode::Idle => 255,
                    _ => 239,
                }; 6],
            ),
            OutputVar::SafetyMode => Value::Int32(self.safety_mode.code()),
            OutputVar::RuntimeState => Value::Uint32(self.runtime.code() as u32),
            OutputVar::RobotStatusBits => {
                let power = u32::from(matches!(
                    self.robot_mode,
                    RobotMode::Idle
                        | RobotMode::Running
                        | RobotMode::PowerOn
                        | RobotMode::Backdrive
                ));
                let running = u32::from(self.runtime == RuntimeState::Playing) << 1;
                Value::Uint32(power | running)
            }
            OutputVar::SafetyStatusBits => Value::Uint32(self.safety_bits()),
            OutputVar::SpeedScaling | OutputVar::SpeedFraction => Value::Double(self.scaling()),
            OutputVar::Temperatures => Value::Vector6d([32.0; 6]),
            OutputVar::Voltage => Value::Double(48.0),
            OutputVar::JointVoltage => Value::Vector6d([48.0; 6]),
            OutputVar::ExecutionTime => Value::Double(0.3),
            OutputVar::Gravity => Value::Vector3d([0.0, 0.0, 9.82]),
            OutputVar::ElbowPosition => {
                let f = self.arm.link_frames(&self.q);
                let p = f[2].translation.vector;
                Value::Vector3d([p.x, p.y, p.z])
            }
            OutputVar::OutInt(i) => Value::Int32(self.regs.out_int[i.min(NREG - 1)]),
            OutputVar::OutDouble(i) => Value::Double(self.regs.out_double[i.min(NREG - 1)]),
            OutputVar::InInt(i) => Value::Int32(self.regs.in_int[i.min(NREG - 1)]),
            OutputVar::InDouble(i) => Value::Double(self.regs.in_double[i.min(NREG - 1)]),
            OutputVar::OutBits(hi) => Value::Uint32(self.regs.out_bits[usize::from(hi)]),
            OutputVar::InBits(hi) => Value::Uint32(self.regs.in_bits[usize::from(hi)]),
            OutputVar::DigitalOut => Value::Uint64(self.io.digital_outputs()),
            OutputVar::DigitalIn => Value::Uint64(self.io.digital_inputs()),
            OutputVar::ConfigurableOut => Value::Uint64((self.io.digital_outputs() >> 8) & 0xff),
            OutputVar::ConfigurableIn => Value::Uint64((self.io.digital_inputs() >> 8) & 0xff),
            OutputVar::AnalogOut(ch) => Value::Double(self.io.analog_output(ch)),
            OutputVar::Zero(t) => t.zero(),
        }
    }
}
