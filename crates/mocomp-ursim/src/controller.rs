//! The simulated controller itself, without I/O: joint dynamics, the register store, the
//! programs it runs natively (mocomp's and ur_rtde's), safety modes, and every RTDE output.
//! One call to [`Controller::step`] is one controller cycle (2 ms e-Series, 8 ms CB3).
//!
//! # Joint model
//! - `servoj(q, t, lookahead, gain)`: the joint reference accelerates with
//!   `gain · (q_target − q − lookahead · q̇)`, limited by the joint acceleration and speed. A
//!   target moving at constant speed `v` is followed with a lag of `lookahead · v` (the lag the
//!   UR servo shows: low lookahead reacts fast, a high one overshoots less), a step settles with
//!   damping `lookahead · √gain / 2`.
//! - `speedj(q̇, a)`: the speed ramps to `q̇` at `a`. `movej(q, v, a)`: a synchronised trapezoid
//!   (the joint with the longest way sets the time). `stopj(a)`: decelerate at `a`.
//! - Speed scaling (the speed slider, `speed_slider_fraction`) stretches time for all three, as
//!   on the real controller.
//! - The reported target and actual joints are the reference itself (a perfect joint servo).
//!
//! # Protective stops
//! A servo setpoint that implies a joint speed above `setpoint_speed_factor` × the joint's
//! maximum (a jump; URControl's "C204A3 invalid setpoints"), a speed command above the maximum,
//! and any joint reaching its position limit stop the arm at `stop_decel` and stop the program,
//! with `safety_mode` 3 and `safety_status_bits` bit 2, until the dashboard unlocks it.

use mocomp_geom::{nalgebra::Vector6, ur_pose_from_iso};
use mocomp_kin::{Arm, Model, ModelSpec};
use mocomp_ur::codec::ControllerVersion;
use mocomp_ur::program::{self as mp, cmd as mcmd, mode as mmode};
use mocomp_ur::robot::{RobotMode, RuntimeState, SafetyMode};
use mocomp_ur::types::{DataType, REGISTERS, Value, input_type, output_type};
use std::collections::VecDeque;

const NREG: usize = REGISTERS as usize;

/// Simulator settings.
#[derive(Debug, Clone)]
pub struct ControllerConfig {
    /// The arm.
    pub model: Model,
    /// Reported software version (`None`: 5.11.1.108318 for e-Series, 3.15.7.106331 for CB3).
    pub version: Option<ControllerVersion>,
    /// Serial number (digits).
    pub serial: String,
    /// Joint accelerations limit, rad/s² (an assumption: UR does not publish one).
    pub max_accel: [f64; 6],
    /// Deceleration of protective and program stops, rad/s².
    pub stop_decel: f64,
    /// A servo setpoint implying more than this times the maximum joint speed is a jump.
    pub setpoint_speed_factor: f64,
    /// Seconds after a protective stop before the dashboard may unlock it (the real
    /// controller is reported to refuse within about 5 s; 0 here by default).
    pub unlock_delay_s: f64,
    /// Start powered with brakes released (`RUNNING`), else `POWER_OFF`.
    pub powered: bool,
    /// Initial joints, rad.
    pub initial_q: [f64; 6],
}

impl ControllerConfig {
    /// Defaults for `model`: running, at a working pose away from singularities and limits.
    pub fn new(model: Model) -> Self {
        Self {
            model,
            version: None,
            serial: "20235500001".into(),
            max_accel: [40.0; 6],
            stop_decel: 10.0,
            setpoint_speed_factor: 1.2,
            unlock_delay_s: 0.0,
            powered: true,
            initial_q: [0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
        }
    }

    /// The version reported.
    pub fn version(&self) -> ControllerVersion {
        self.version.unwrap_or(match self.model.spec().series {
            mocomp_kin::Series::Cb3 => ControllerVersion {
                major: 3,
                minor: 15,
                bugfix: 7,
                build: 106331,
            },
            mocomp_kin::Series::ESeries => ControllerVersion {
                major: 5,
                minor: 11,
                bugfix: 1,
                build: 108318,
            },
        })
    }
}

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
    /// An I/O variable the simulator accepts and ignores (digital/analog outputs, wrench).
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

/// One thing the simulator did or refused, with its controller time.
#[derive(Debug, Clone, PartialEq)]
pub struct SimEvent {
    /// Controller time, s.
    pub time_s: f64,
    /// What happened.
    pub text: String,
}

#[derive(Debug, Clone, Copy)]
struct Servo {
    target: [f64; 6],
    lookahead: f64,
    gain: f64,
    changed_s: f64,
}

#[derive(Debug, Clone, Copy)]
struct MoveProfile {
    start: [f64; 6],
    delta: [f64; 6],
    dist: f64,
    v: f64,
    a: f64,
    t_acc: f64,
    t_total: f64,
    elapsed: f64,
}

impl MoveProfile {
    fn new(start: [f64; 6], goal: [f64; 6], v: f64, a: f64) -> Self {
        let delta: [f64; 6] = std::array::from_fn(|j| goal[j] - start[j]);
        let dist = delta.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        let (v, t_acc, t_total) = if dist <= 0.0 {
            (v, 0.0, 0.0)
        } else if dist < v * v / a {
            let ta = (dist / a).sqrt();
            (a * ta, ta, 2.0 * ta)
        } else {
            (v, v / a, dist / v + v / a)
        };
        Self {
            start,
            delta,
            dist,
            v,
            a,
            t_acc,
            t_total,
            elapsed: 0.0,
        }
    }

    /// Fraction of the way done at `t`.
    fn fraction(&self, t: f64) -> f64 {
        if self.dist <= 0.0 || t >= self.t_total {
            return 1.0;
        }
        let s = if t < self.t_acc {
            0.5 * self.a * t * t
        } else if t < self.t_total - self.t_acc {
            0.5 * self.a * self.t_acc * self.t_acc + self.v * (t - self.t_acc)
        } else {
            let r = self.t_total - t;
            self.dist - 0.5 * self.a * r * r
        };
        (s / self.dist).clamp(0.0, 1.0)
    }
}

#[derive(Debug, Clone, Copy)]
enum Motion {
    Idle,
    Servo(Servo),
    Speed { qd: [f64; 6], accel: f64 },
    Move(MoveProfile),
    Stop { decel: f64 },
}

#[derive(Debug, Clone, Copy)]
struct MocompProgram {
    last_seq: i32,
    mode: i32,
    move_seq: i32,
    blocked_stop: bool,
}

#[derive(Debug, Clone, Copy)]
struct RtdeProgram {
    off_int: usize,
    off_double: usize,
    executing: bool,
    /// Inside a blocking `process_cmd` until the motion ends (then DONE is signalled).
    blocking: bool,
}

#[derive(Debug, Clone, Copy)]
enum Program {
    None,
    Mocomp(MocompProgram),
    UrRtde(RtdeProgram),
}

#[derive(Debug, Clone, Copy)]
struct Watchdog {
    register: usize,
    hz: f64,
    since_s: f64,
}

/// The register store.
#[derive(Debug, Clone)]
struct Registers {
    in_int: [i32; NREG],
    in_double: [f64; NREG],
    in_bits: [u32; 2],
    in_bit_hi: [bool; 64],
    out_int: [i32; NREG],
    out_double: [f64; NREG],
    out_bits: [u32; 2],
    in_int_updated_s: [f64; NREG],
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

/// Kept events (older ones are dropped).
const MAX_EVENTS: usize = 256;

/// The simulated controller.
#[derive(Debug, Clone)]
pub struct Controller {
    config: ControllerConfig,
    spec: &'static ModelSpec,
    arm: Arm,
    period: f64,
    tick: u64,
    time_s: f64,
    q: [f64; 6],
    qd_int: [f64; 6],
    qd: [f64; 6],
    qdd: [f64; 6],
    motion: Motion,
    program: Program,
    watchdog: Option<Watchdog>,
    regs: Registers,
    slider_mask: u32,
    slider: f64,
    robot_mode: RobotMode,
    safety_mode: SafetyMode,
    runtime: RuntimeState,
    stopped_at_s: f64,
    events: VecDeque<SimEvent>,
    events_total: u64,
    protective_stops: u64,
}

/// A program text the simulator recognises.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ProgramKind {
    /// mocomp's control program (its watchdog, Hz).
    Mocomp {
        /// Watchdog frequency from the program text.
        watchdog_hz: f64,
    },
    /// ur_rtde's `rtde_control` script, with its register offsets.
    UrRtde {
        /// Integer register offset (0 or 24).
        off_int: usize,
        /// Double register offset (0 or 24).
        off_double: usize,
    },
    /// Any other program: the simulator does not interpret URScript.
    Unsupported,
}

/// Classifies a complete program text (a `def …():` … `end` block).
pub fn classify_program(text: &str) -> ProgramKind {
    let first = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("");
    if first.trim_end() == mp::PROGRAM_HEADER && text.contains(mp::PROTOCOL_MARKER) {
        return ProgramKind::Mocomp {
            watchdog_hz: mp::watchdog_hz_in(text).unwrap_or(0.0),
        };
    }
    if first.starts_with("def rtde_control():") && text.contains("RTDE Control Script") {
        let offset = |key: &str| {
            text.lines()
                .find_map(|l| l.split_once(key).map(|(_, r)| r))
                .and_then(|r| r.trim_start_matches([' ', '=']).split_whitespace().next())
                .and_then(|n| n.parse::<usize>().ok())
                .filter(|n| *n == 0 || *n == 24)
                .unwrap_or(0)
        };
        return ProgramKind::UrRtde {
            off_int: offset("reg_offset_int"),
            off_double: offset("reg_offset_float"),
        };
    }
    ProgramKind::Unsupported
}

fn approach(v: f64, target: f64, step: f64) -> f64 {
    if (target - v).abs() <= step {
        target
    } else {
        v + step * (target - v).signum()
    }
}

impl Controller {
    /// A controller in its initial state.
    pub fn new(config: ControllerConfig) -> Self {
        let spec = config.model.spec();
        let powered = config.powered;
        Self {
            spec,
            arm: Arm::new(config.model),
            period: spec.series.period_s(),
            tick: 0,
            time_s: 0.0,
            q: config.initial_q,
            qd_int: [0.0; 6],
            qd: [0.0; 6],
            qdd: [0.0; 6],
            motion: Motion::Idle,
            program: Program::None,
            watchdog: None,
            regs: Registers::default(),
            slider_mask: 0,
            slider: 1.0,
            robot_mode: if powered {
                RobotMode::Running
            } else {
                RobotMode::PowerOff
            },
            safety_mode: SafetyMode::Normal,
            runtime: RuntimeState::Stopped,
            stopped_at_s: f64::NEG_INFINITY,
            events: VecDeque::new(),
            events_total: 0,
            protective_stops: 0,
            config,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &ControllerConfig {
        &self.config
    }

    /// Control period, s.
    pub fn period_s(&self) -> f64 {
        self.period
    }

    /// Controller time, s.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Cycles run.
    pub fn ticks(&self) -> u64 {
        self.tick
    }

    /// Joint positions, rad.
    pub fn q(&self) -> [f64; 6] {
        self.q
    }

    /// Joint velocities, rad/s.
    pub fn qd(&self) -> [f64; 6] {
        self.qd
    }

    /// Robot mode.
    pub fn robot_mode(&self) -> RobotMode {
        self.robot_mode
    }

    /// Safety mode.
    pub fn safety_mode(&self) -> SafetyMode {
        self.safety_mode
    }

    /// Program state.
    pub fn runtime_state(&self) -> RuntimeState {
        self.runtime
    }

    /// Protective stops so far.
    pub fn protective_stops(&self) -> u64 {
        self.protective_stops
    }

    /// The newest events (at most 256 kept) and how many there were in all.
    pub fn events(&self) -> (Vec<SimEvent>, u64) {
        (self.events.iter().cloned().collect(), self.events_total)
    }

    /// Output register value (for tests).
    pub fn output_int(&self, i: usize) -> i32 {
        self.regs.out_int.get(i).copied().unwrap_or(0)
    }

    /// Input register value (for tests).
    pub fn input_int(&self, i: usize) -> i32 {
        self.regs.in_int.get(i).copied().unwrap_or(0)
    }

    /// Records an event (the servers log protocol problems here too).
    pub fn record_event(&mut self, text: String) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
        }
        self.events_total += 1;
        self.events.push_back(SimEvent {
            time_s: self.time_s,
            text,
        });
    }

    fn scaling(&self) -> f64 {
        if self.slider_mask & 1 != 0 {
            self.slider.clamp(0.0, 1.0)
        } else {
            1.0
        }
    }

    fn can_move(&self) -> bool {
        self.robot_mode == RobotMode::Running
            && matches!(self.safety_mode, SafetyMode::Normal | SafetyMode::Reduced)
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
            _ => {}
        }
    }

    /// Loads a complete program text received on a script port (stopping any program running).
    pub fn load_program(&mut self, text: &str) {
        let kind = classify_program(text);
        if !matches!(self.program, Program::None) || self.runtime == RuntimeState::Playing {
            self.stop_program("a new program was sent".into());
        }
        if !self.can_move() {
            self.record_event(format!(
                "program not started: robot mode {}, safety mode {}",
                self.robot_mode, self.safety_mode
            ));
            return;
        }
        match kind {
            ProgramKind::Mocomp { watchdog_hz } => {
                self.program = Program::Mocomp(MocompProgram {
                    last_seq: self.regs.in_int[25],
                    mode: mmode::IDLE,
                    move_seq: 0,
                    blocked_stop: false,
                });
                self.regs.out_int[26] = mp::PROTOCOL_ID;
                self.regs.out_int[27] = 0;
                self.regs.out_int[24] = mmode::IDLE;
                self.regs.out_int[25] = self.regs.in_int[25];
                self.watchdog = (watchdog_hz > 0.0).then_some(Watchdog {
                    register: 25,
                    hz: watchdog_hz,
                    since_s: self.time_s,
                });
                self.record_event(format!(
                    "mocomp control program started (watchdog {watchdog_hz} Hz)"
                ));
            }
            ProgramKind::UrRtde {
                off_int,
                off_double,
            } => {
                self.program = Program::UrRtde(RtdeProgram {
                    off_int,
                    off_double,
                    executing: false,
                    blocking: false,
                });
                self.regs.out_int[off_int] = 1;
                self.watchdog = None;
                self.record_event(format!(
                    "ur_rtde control script started (register offset {off_int})"
                ));
            }
            ProgramKind::Unsupported => {
                let first = text.lines().next().unwrap_or("").chars().take(60);
                self.record_event(format!(
                    "program {:?} not run: the simulator runs only mocomp's and ur_rtde's \
                     control programs",
                    first.collect::<String>()
                ));
                return;
            }
        }
        self.runtime = RuntimeState::Playing;
    }

    /// Stops the program (dashboard `stop`, watchdog, fault); the arm decelerates.
    pub fn stop_program(&mut self, why: String) {
        if matches!(self.program, Program::None) && self.runtime != RuntimeState::Playing {
            return;
        }
        self.program = Program::None;
        self.watchdog = None;
        self.runtime = RuntimeState::Stopped;
        if !matches!(self.motion, Motion::Idle) {
            self.motion = Motion::Stop { decel: 4.0 };
        }
        self.record_event(format!("program stopped: {why}"));
    }

    /// Enters a protective stop.
    pub fn protective_stop(&mut self, why: String) {
        if self.safety_mode == SafetyMode::ProtectiveStop {
            return;
        }
        self.protective_stops += 1;
        self.safety_mode = SafetyMode::ProtectiveStop;
        self.stopped_at_s = self.time_s;
        self.record_event(format!("protective stop: {why}"));
        self.program = Program::None;
        self.watchdog = None;
        self.runtime = RuntimeState::Stopped;
        self.motion = Motion::Stop {
            decel: self.config.stop_decel,
        };
    }

    /// Presses the emergency stop: the arm stops and powers off.
    pub fn emergency_stop(&mut self) {
        self.safety_mode = SafetyMode::RobotEmergencyStop;
        self.record_event("emergency stop pressed".into());
        self.program = Program::None;
        self.watchdog = None;
        self.runtime = RuntimeState::Stopped;
        self.motion = Motion::Stop {
            decel: self.config.stop_decel,
        };
    }

    /// Releases the emergency stop: safety normal, the arm stays powered off.
    pub fn release_emergency_stop(&mut self) {
        if matches!(
            self.safety_mode,
            SafetyMode::RobotEmergencyStop | SafetyMode::SystemEmergencyStop
        ) {
            self.safety_mode = SafetyMode::Normal;
            self.robot_mode = RobotMode::PowerOff;
            self.record_event("emergency stop released; power on and release the brakes".into());
        }
    }

    // ---------------------------------------------------------------- dashboard

    /// Answers one dashboard command line (without the line end).
    pub fn dashboard(&mut self, line: &str) -> String {
        let line = line.trim();
        let lower = line.to_ascii_lowercase();
        let v = self.config.version();
        match lower.as_str() {
            "power on" => {
                if matches!(
                    self.safety_mode,
                    SafetyMode::RobotEmergencyStop | SafetyMode::SystemEmergencyStop
                ) {
                    return "Failed to power on: emergency stop active".into();
                }
                if matches!(self.robot_mode, RobotMode::PowerOff | RobotMode::PowerOn) {
                    self.robot_mode = RobotMode::Idle;
                }
                "Powering on".into()
            }
            "power off" => {
                self.stop_program("power off".into());
                self.robot_mode = RobotMode::PowerOff;
                self.motion = Motion::Idle;
                self.qd = [0.0; 6];
                self.qd_int = [0.0; 6];
                "Powering off".into()
            }
            "brake release" => {
                if self.robot_mode == RobotMode::Idle {
                    self.robot_mode = RobotMode::Running;
                }
                "Brake releasing".into()
            }
            "play" => "Failed to execute: play (no program loaded in the simulator)".into(),
            "stop" => {
                self.stop_program("dashboard stop".into());
                "Stopped".into()
            }
            "pause" => "Failed to execute: pause".into(),
            "robotmode" => format!("Robotmode: {}", self.robot_mode.name()),
            "safetymode" => format!("Safetymode: {}", self.safety_mode.name()),
            "safetystatus" => format!("Safetystatus: {}", self.safety_mode.name()),
            "programstate" => {
                let state = if self.runtime == RuntimeState::Playing {
                    "PLAYING"
                } else {
                    "STOPPED"
                };
                let name = match self.program {
                    Program::Mocomp(_) => "mocomp_control",
                    Program::UrRtde(_) => "rtde_control",
                    Program::None => "<unnamed>",
                };
                format!("{state} {name}")
            }
            "running" => format!("Program running: {}", self.runtime == RuntimeState::Playing),
            "unlock protective stop" => {
                if self.safety_mode != SafetyMode::ProtectiveStop {
                    return "Protective stop releasing".into();
                }
                if self.time_s - self.stopped_at_s < self.config.unlock_delay_s {
                    return "Cannot unlock protective stop until 5s after occurrence. Always \
                            inspect cause of protective stop before unlocking"
                        .into();
                }
                self.safety_mode = SafetyMode::Normal;
                self.record_event("protective stop unlocked".into());
                "Protective stop releasing".into()
            }
            "close safety popup" => "closing safety popup".into(),
            "close popup" => "closing popup".into(),
            "restart safety" => {
                if self.safety_mode != SafetyMode::Normal {
                    self.safety_mode = SafetyMode::Normal;
                    self.robot_mode = RobotMode::PowerOff;
                }
                "Restarting safety".into()
            }
            "polyscopeversion" => format!("URSoftware {v} (simulated by mocomp)"),
            "version" => v.to_string(),
            "is in remote control" => "true".into(),
            "get serial number" => self.config.serial.clone(),
            "get robot model" => self.config.model.name().to_ascii_uppercase(),
            "quit" => "Disconnected".into(),
            "shutdown" => "Shutting down".into(),
            "get loaded program" => "No program loaded".into(),
            _ if lower.starts_with("load ") => {
                format!("File not found: {}", line[5..].trim())
            }
            _ => format!("could not understand: '{line}'"),
        }
    }

    // ---------------------------------------------------------------- one cycle

    /// Runs one controller cycle.
    pub fn step(&mut self) {
        self.tick += 1;
        self.time_s = self.tick as f64 * self.period;
        self.check_watchdog();
        self.run_program();
        self.integrate();
        self.check_limits();
        self.finish_program_waits();
    }

    fn check_watchdog(&mut self) {
        let Some(w) = self.watchdog else { return };
        let last = self.regs.in_int_updated_s[w.register].max(w.since_s);
        if self.time_s - last > 1.0 / w.hz + 1e-9 {
            self.stop_program(format!(
                "RTDE watchdog: input_int_register_{} not updated for {:.0} ms (limit {:.0} ms)",
                w.register,
                (self.time_s - last) * 1e3,
                1e3 / w.hz
            ));
        }
    }

    fn read_q(&self, base: usize) -> [f64; 6] {
        std::array::from_fn(|j| self.regs.in_double[(base + j).min(NREG - 1)])
    }

    fn start_servo(&mut self, target: [f64; 6], t: f64, lookahead: f64, gain: f64) -> bool {
        if !(0.001..=1.0).contains(&t)
            || !(0.03..=0.2).contains(&lookahead)
            || !(100.0..=2000.0).contains(&gain)
        {
            self.stop_program(format!(
                "servoj: t = {t}, lookahead_time = {lookahead}, gain = {gain} outside \
                 [0.001, 1], [0.03, 0.2], [100, 2000]"
            ));
            return false;
        }
        let (prev, since) = match self.motion {
            Motion::Servo(s) => (s.target, s.changed_s),
            _ => (self.q, self.time_s - t),
        };
        if target != prev {
            let dt = (self.time_s - since).max(t).max(self.period);
            for j in 0..6 {
                let limit = self.spec.max_speed[j] * self.config.setpoint_speed_factor;
                let v = (target[j] - prev[j]).abs() / dt;
                if !v.is_finite() || v > limit {
                    self.protective_stop(format!(
                        "C204A3 invalid setpoint: joint {} servo target moves {:.4} rad in \
                         {:.1} ms ({:.2} rad/s, limit {:.2})",
                        j + 1,
                        (target[j] - prev[j]).abs(),
                        dt * 1e3,
                        v,
                        limit
                    ));
                    return false;
                }
            }
            if !self.arm.limits().contains(&target, 0.0) {
                self.protective_stop("servo target outside the joint limits".into());
                return false;
            }
        }
        let changed_s = if target != prev || !matches!(self.motion, Motion::Servo(_)) {
            self.time_s
        } else {
            since
        };
        self.motion = Motion::Servo(Servo {
            target,
            lookahead,
            gain,
            changed_s,
        });
        true
    }

    fn start_speed(&mut self, qd: [f64; 6], accel: f64) -> bool {
        for (j, v) in qd.iter().enumerate() {
            if !v.is_finite() || v.abs() > self.spec.max_speed[j] {
                self.protective_stop(format!(
                    "joint {} speed command {v:.3} rad/s above its limit {:.3}",
                    j + 1,
                    self.spec.max_speed[j]
                ));
                return false;
            }
        }
        let accel = if accel.is_finite() && accel > 0.0 {
            accel
        } else {
            1.4
        };
        self.motion = Motion::Speed { qd, accel };
        true
    }

    fn start_move(&mut self, goal: [f64; 6], v: f64, a: f64) -> bool {
        if !goal.iter().all(|x| x.is_finite()) || !self.arm.limits().contains(&goal, 0.0) {
            self.stop_program("movej: target outside the joint limits".into());
            return false;
        }
        let v = if v.is_finite() && v > 0.0 {
            v.min(
                self.spec
                    .max_speed
                    .iter()
                    .fold(f64::INFINITY, |m, x| m.min(*x)),
            )
        } else {
            1.05
        };
        let a = if a.is_finite() && a > 0.0 {
            a.min(40.0)
        } else {
            1.4
        };
        self.motion = Motion::Move(MoveProfile::new(self.q, goal, v, a));
        true
    }

    fn run_program(&mut self) {
        if !self.can_move() {
            return;
        }
        match self.program {
            Program::None => {}
            Program::Mocomp(p) => self.run_mocomp(p),
            Program::UrRtde(p) => self.run_ur_rtde(p),
        }
    }

    fn run_mocomp(&mut self, mut p: MocompProgram) {
        if p.blocked_stop {
            return; // inside a blocking stopj
        }
        let b = mp::REGISTER_BASE as usize;
        let command = self.regs.in_int[b];
        let seq = self.regs.in_int[b + 1];
        let d = |k: usize| self.regs.in_double[b + k];
        match command {
            mcmd::SERVOJ => {
                if !self.start_servo(self.read_q(b), d(6), d(7), d(8)) {
                    return;
                }
                p.mode = mmode::SERVO;
            }
            mcmd::SPEEDJ => {
                if !self.start_speed(self.read_q(b), d(6)) {
                    return;
                }
                p.mode = mmode::SPEED;
            }
            _ if seq != p.last_seq => match command {
                mcmd::MOVEJ => {
                    if !self.start_move(self.read_q(b), d(6), d(7)) {
                        return;
                    }
                    p.move_seq = seq;
                    p.mode = mmode::MOVING;
                }
                mcmd::STOPJ => {
                    let a = if d(6).is_finite() && d(6) > 0.0 {
                        d(6)
                    } else {
                        4.0
                    };
                    self.motion = Motion::Stop { decel: a };
                    p.mode = mmode::STOPPING;
                    p.blocked_stop = true;
                }
                mcmd::EXIT => {
                    self.regs.out_int[b] = mmode::NOT_RUNNING;
                    self.regs.out_int[b + 2] = 0;
                    self.regs.out_int[b + 1] = seq;
                    self.stop_program("the control program received EXIT".into());
                    return;
                }
                _ => {}
            },
            _ => {}
        }
        p.last_seq = seq;
        self.regs.out_int[b + 1] = seq;
        self.regs.out_int[b] = p.mode;
        self.program = Program::Mocomp(p);
    }

    fn run_ur_rtde(&mut self, mut p: RtdeProgram) {
        if p.blocking {
            return; // inside process_cmd until the motion ends
        }
        let oi = p.off_int;
        let command = self.regs.in_int[oi];
        const REALTIME: [i32; 11] = [6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66];
        if REALTIME.contains(&command) || (66..=71).contains(&command) {
            if !self.process_ur_rtde(&mut p, command) {
                return;
            }
            self.regs.out_int[oi] = 1;
        } else if command == 0 {
            p.executing = false;
            self.regs.out_int[oi] = 1;
        } else if !p.executing {
            if !self.process_ur_rtde(&mut p, command) {
                return;
            }
            p.executing = true;
            if !p.blocking {
                self.regs.out_int[oi] = 2;
            }
        }
        self.program = Program::UrRtde(p);
    }

    /// One ur_rtde command; false when the program ended.
    fn process_ur_rtde(&mut self, p: &mut RtdeProgram, command: i32) -> bool {
        let od = p.off_double;
        let d = |k: usize| self.regs.in_double[(od + k).min(NREG - 1)];
        let i1 = self.regs.in_int[(p.off_int + 1).min(NREG - 1)];
        match command {
            1 => {
                if !self.start_move(self.read_q(od), d(6), d(7)) {
                    return false;
                }
                if i1 == 0 {
                    p.blocking = true;
                }
            }
            9 => {
                if !self.start_speed(self.read_q(od), d(6)) {
                    return false;
                }
            }
            11 => {
                if !self.start_servo(self.read_q(od), d(8), d(9), d(10)) {
                    return false;
                }
            }
            15 | 16 | 34 => {
                let a = if d(0).is_finite() && d(0) > 0.0 {
                    d(0)
                } else {
                    10.0
                };
                self.motion = Motion::Stop { decel: a };
                if command != 34 || i1 == 0 {
                    p.blocking = true;
                }
            }
            35 => {
                let hz = d(0);
                if hz.is_finite() && hz > 0.0 {
                    self.watchdog = Some(Watchdog {
                        register: p.off_int,
                        hz,
                        since_s: self.time_s,
                    });
                }
            }
            26 => self.regs.out_double[od] = self.period,
            255 => {
                self.record_event("ur_rtde: Received stop script!".into());
                self.stop_program("ur_rtde STOP_SCRIPT".into());
                return false;
            }
            other => self.record_event(format!(
                "ur_rtde command {other} is not emulated; acknowledged without effect"
            )),
        }
        true
    }

    fn finish_program_waits(&mut self) {
        let idle = matches!(self.motion, Motion::Idle);
        match &mut self.program {
            Program::UrRtde(p) => {
                if p.blocking && idle {
                    p.blocking = false;
                    let oi = p.off_int;
                    self.regs.out_int[oi] = 2;
                }
            }
            Program::Mocomp(p) => {
                let b = mp::REGISTER_BASE as usize;
                if p.blocked_stop && idle {
                    p.blocked_stop = false;
                    p.mode = mmode::IDLE;
                    self.regs.out_int[b] = mmode::IDLE;
                    self.regs.out_int[b + 1] = p.last_seq;
                }
                if p.mode == mmode::MOVING && idle {
                    p.mode = mmode::IDLE;
                    self.regs.out_int[b] = mmode::IDLE;
                    self.regs.out_int[b + 3] = p.move_seq;
                }
            }
            Program::None => {}
        }
    }

    fn integrate(&mut self) {
        let dt = self.period;
        let ds = dt * self.scaling();
        let q0 = self.q;
        let qd0 = self.qd;
        match &mut self.motion {
            Motion::Idle => {
                for j in 0..6 {
                    self.qd_int[j] = approach(self.qd_int[j], 0.0, self.config.stop_decel * dt);
                    self.q[j] += self.qd_int[j] * dt;
                }
            }
            Motion::Servo(s) => {
                for j in 0..6 {
                    let vmax = self.spec.max_speed[j];
                    let amax = self.config.max_accel[j];
                    let acc = (s.gain * (s.target[j] - self.q[j] - s.lookahead * self.qd_int[j]))
                        .clamp(-amax, amax);
                    self.qd_int[j] = (self.qd_int[j] + acc * ds).clamp(-vmax, vmax);
                    self.q[j] += self.qd_int[j] * ds;
                }
            }
            Motion::Speed { qd, accel } => {
                for ((v, target), q) in self.qd_int.iter_mut().zip(qd.iter()).zip(&mut self.q) {
                    *v = approach(*v, *target, *accel * ds);
                    *q += *v * ds;
                }
            }
            Motion::Move(m) => {
                m.elapsed += ds;
                let f = m.fraction(m.elapsed);
                for j in 0..6 {
                    let next = m.start[j] + m.delta[j] * f;
                    self.qd_int[j] = (next - self.q[j]) / ds.max(1e-12);
                    self.q[j] = next;
                }
                if m.elapsed >= m.t_total {
                    self.qd_int = [0.0; 6];
                    self.motion = Motion::Idle;
                }
            }
            Motion::Stop { decel } => {
                let mut moving = false;
                for j in 0..6 {
                    self.qd_int[j] = approach(self.qd_int[j], 0.0, *decel * dt);
                    self.q[j] += self.qd_int[j] * dt;
                    moving |= self.qd_int[j] != 0.0;
                }
                if !moving {
                    self.motion = Motion::Idle;
                }
            }
        }
        for j in 0..6 {
            self.qd[j] = (self.q[j] - q0[j]) / dt;
            self.qdd[j] = (self.qd[j] - qd0[j]) / dt;
        }
    }

    fn check_limits(&mut self) {
        let lim = *self.arm.limits();
        for j in 0..6 {
            if self.q[j] < lim.lower[j] || self.q[j] > lim.upper[j] {
                self.q[j] = self.q[j].clamp(lim.lower[j], lim.upper[j]);
                self.qd_int = [0.0; 6];
                self.protective_stop(format!("joint {} reached its position limit", j + 1));
                self.motion = Motion::Idle;
            }
        }
    }

    // ---------------------------------------------------------------- outputs

    fn safety_bits(&self) -> u32 {
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
            OutputVar::Zero(t) => t.zero(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn servo_inputs(c: &mut Controller, q: [f64; 6], seq: i32) {
        c.apply_input(InputSlot::Int(24), Value::Int32(mcmd::SERVOJ));
        c.apply_input(InputSlot::Int(25), Value::Int32(seq));
        for (j, x) in q.iter().enumerate() {
            c.apply_input(InputSlot::Double(24 + j), Value::Double(*x));
        }
        c.apply_input(InputSlot::Double(30), Value::Double(0.002));
        c.apply_input(InputSlot::Double(31), Value::Double(0.05));
        c.apply_input(InputSlot::Double(32), Value::Double(1000.0));
    }

    /// Steps `n` cycles while the client keeps resending its last package (feeds the watchdog).
    fn step_fed(c: &mut Controller, n: usize) {
        for _ in 0..n {
            let seq = c.input_int(25);
            c.apply_input(InputSlot::Int(25), Value::Int32(seq));
            c.step();
        }
    }

    fn running(model: Model) -> Controller {
        let mut c = Controller::new(ControllerConfig::new(model));
        c.load_program(&mp::script(20.0));
        assert_eq!(c.runtime_state(), RuntimeState::Playing);
        c
    }

    #[test]
    fn servo_follows_a_ramp_with_the_lookahead_lag() {
        let mut c = running(Model::Ur5e);
        let q0 = c.q();
        let v = 0.2; // rad/s on joint 1
        for k in 1..=1500 {
            let mut q = q0;
            q[0] += v * k as f64 * 0.002;
            servo_inputs(&mut c, q, k);
            c.step();
        }
        let lag = q0[0] + v * 3.0 - c.q()[0];
        // Steady-state lag = lookahead · v = 0.05 · 0.2 = 0.01 rad (minus one cycle of delay).
        assert!((lag - 0.01).abs() < 0.001, "lag {lag}");
        assert!((c.qd()[0] - v).abs() < 1e-6);
        assert_eq!(c.output_int(25), 1500, "acknowledged sequence");
        assert_eq!(c.safety_mode(), SafetyMode::Normal);
    }

    #[test]
    fn a_servo_jump_is_a_protective_stop() {
        let mut c = running(Model::Ur3e);
        let mut q = c.q();
        q[2] += 0.1; // 0.1 rad in 2 ms = 50 rad/s
        servo_inputs(&mut c, q, 1);
        c.step();
        assert_eq!(c.safety_mode(), SafetyMode::ProtectiveStop);
        assert_eq!(c.runtime_state(), RuntimeState::Stopped);
        assert_eq!(c.protective_stops(), 1);
        let (ev, _) = c.events();
        assert!(
            ev.iter()
                .any(|e| e.text.contains("C204A3") && e.text.contains("joint 3"))
        );
        assert_eq!(
            c.dashboard("unlock protective stop"),
            "Protective stop releasing"
        );
        assert_eq!(c.safety_mode(), SafetyMode::Normal);
    }

    #[test]
    fn the_watchdog_stops_the_program_when_inputs_stop() {
        let mut c = running(Model::Ur3e); // 20 Hz: 50 ms
        for k in 1..=10 {
            let q = c.q();
            servo_inputs(&mut c, q, k);
            c.step();
        }
        for _ in 0..24 {
            c.step();
        }
        assert_eq!(
            c.runtime_state(),
            RuntimeState::Playing,
            "48 ms silent: still fine"
        );
        for _ in 0..3 {
            c.step();
        }
        assert_eq!(c.runtime_state(), RuntimeState::Stopped);
        let (ev, _) = c.events();
        assert!(
            ev.iter().any(|e| e.text.contains("RTDE watchdog")),
            "{ev:?}"
        );
    }

    #[test]
    fn movej_is_a_synchronised_trapezoid() {
        let mut c = running(Model::Ur5);
        let q0 = c.q();
        let mut goal = q0;
        goal[0] += 1.0;
        goal[3] -= 0.5;
        c.apply_input(InputSlot::Int(24), Value::Int32(mcmd::MOVEJ));
        c.apply_input(InputSlot::Int(25), Value::Int32(7));
        for (j, x) in goal.iter().enumerate() {
            c.apply_input(InputSlot::Double(24 + j), Value::Double(*x));
        }
        c.apply_input(InputSlot::Double(30), Value::Double(1.0));
        c.apply_input(InputSlot::Double(31), Value::Double(2.0));
        // T = 1/1 + 1/2 = 1.5 s at 125 Hz.
        let mut max_v: f64 = 0.0;
        for _ in 0..((1.5 / 0.008) as usize - 2) {
            step_fed(&mut c, 1);
            max_v = max_v.max(c.qd()[0].abs());
            // Joint 4 moves in proportion.
            let f0 = (c.q()[0] - q0[0]) / 1.0;
            let f3 = (c.q()[3] - q0[3]) / -0.5;
            assert!((f0 - f3).abs() < 1e-9);
        }
        assert_ne!(c.output_int(27), 7, "not done yet");
        step_fed(&mut c, 4);
        assert_eq!(c.output_int(27), 7, "done");
        assert!((c.q()[0] - goal[0]).abs() < 1e-12);
        assert!((max_v - 1.0).abs() < 1e-6, "cruise speed {max_v}");
    }

    #[test]
    fn speed_slider_stretches_time() {
        let mut c = running(Model::Ur5e);
        c.apply_input(InputSlot::SliderMask, Value::Uint32(1));
        c.apply_input(InputSlot::SliderFraction, Value::Double(0.5));
        c.apply_input(InputSlot::Int(24), Value::Int32(mcmd::SPEEDJ));
        c.apply_input(InputSlot::Int(25), Value::Int32(1));
        c.apply_input(InputSlot::Double(24), Value::Double(0.4));
        c.apply_input(InputSlot::Double(30), Value::Double(100.0));
        step_fed(&mut c, 100);
        assert!((c.qd()[0] - 0.2).abs() < 1e-9, "{}", c.qd()[0]);
        assert_eq!(c.output(OutputVar::SpeedScaling), Value::Double(0.5));
    }

    #[test]
    fn joint_limits_and_speed_limits_are_protective_stops() {
        let mut cfg = ControllerConfig::new(Model::Ur5e);
        cfg.initial_q[1] = -std::f64::consts::TAU + 0.01; // shoulder 10 mrad from its limit
        let mut c = Controller::new(cfg);
        c.load_program(&mp::script(20.0));
        c.apply_input(InputSlot::Int(24), Value::Int32(mcmd::SPEEDJ));
        c.apply_input(InputSlot::Int(25), Value::Int32(1));
        c.apply_input(InputSlot::Double(25), Value::Double(-0.5));
        c.apply_input(InputSlot::Double(30), Value::Double(10.0));
        step_fed(&mut c, 60);
        assert_eq!(c.safety_mode(), SafetyMode::ProtectiveStop);
        assert!(c.q()[1] >= -std::f64::consts::TAU, "never beyond the limit");
        let (ev, _) = c.events();
        assert!(
            ev.iter()
                .any(|e| e.text.contains("joint 2 reached its position limit"))
        );

        let mut c = running(Model::Ur10); // UR10 base: 120°/s
        c.apply_input(InputSlot::Int(24), Value::Int32(mcmd::SPEEDJ));
        c.apply_input(InputSlot::Int(25), Value::Int32(1));
        c.apply_input(InputSlot::Double(24), Value::Double(2.5));
        c.step();
        assert_eq!(c.safety_mode(), SafetyMode::ProtectiveStop);
        let (ev, _) = c.events();
        assert!(
            ev.iter().any(|e| e.text.contains("joint 1 speed command")),
            "{ev:?}"
        );
    }

    #[test]
    fn power_and_brakes_follow_the_dashboard() {
        let mut cfg = ControllerConfig::new(Model::Ur3);
        cfg.powered = false;
        let mut c = Controller::new(cfg);
        assert_eq!(c.dashboard("robotmode"), "Robotmode: POWER_OFF");
        c.load_program(&mp::script(20.0));
        assert_eq!(
            c.runtime_state(),
            RuntimeState::Stopped,
            "no program without power"
        );
        assert_eq!(c.dashboard("power on"), "Powering on");
        assert_eq!(c.dashboard("robotmode"), "Robotmode: IDLE");
        assert_eq!(c.dashboard("brake release"), "Brake releasing");
        assert_eq!(c.dashboard("robotmode"), "Robotmode: RUNNING");
        assert_eq!(c.dashboard("is in remote control"), "true");
        assert!(
            c.dashboard("get serial number")
                .bytes()
                .all(|b| b.is_ascii_digit())
        );
        assert!(
            c.dashboard("PolyscopeVersion")
                .starts_with("URSoftware 3.15.7.106331")
        );
        c.emergency_stop();
        assert_eq!(
            c.dashboard("power on"),
            "Failed to power on: emergency stop active"
        );
        c.release_emergency_stop();
        assert_eq!(c.dashboard("safetymode"), "Safetymode: NORMAL");
        assert_eq!(c.dashboard("robotmode"), "Robotmode: POWER_OFF");
        assert!(
            c.dashboard("frobnicate")
                .starts_with("could not understand")
        );
    }

    #[test]
    fn programs_are_recognised() {
        assert_eq!(
            classify_program(&mp::script(12.5)),
            ProgramKind::Mocomp { watchdog_hz: 12.5 }
        );
        let rtde = "def rtde_control():\n    global reg_offset_float = 24\n    global reg_offset_int = 24\n    textmsg(\"RTDE Control Script Loaded\")\nend\n";
        assert_eq!(
            classify_program(rtde),
            ProgramKind::UrRtde {
                off_int: 24,
                off_double: 24
            }
        );
        assert_eq!(
            classify_program("def foo():\n  movej([0,0,0,0,0,0])\nend\n"),
            ProgramKind::Unsupported
        );
    }

    #[test]
    fn tcp_output_is_the_kinematic_model() {
        let c = running(Model::Ur10);
        let Value::Vector6d(p) = c.output(OutputVar::TcpPose) else {
            panic!()
        };
        let expect = ur_pose_from_iso(&Arm::new(Model::Ur10).fk(&c.q()));
        assert_eq!(p, expect);
    }
}
