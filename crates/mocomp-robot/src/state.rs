//! The robot as the control loop sees it: the state it reports, and the faults that stop it
//! (the commands are [`crate::command`]'s).

use mocomp_geom::Pose;

macro_rules! code_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = $code:literal, $word:literal;)* }) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub enum $name {
            $($(#[$vm])* $v,)*
            /// A code this table does not know.
            Other(i32),
        }
        impl $name {
            /// From the controller's code.
            pub fn from_code(c: i32) -> Self {
                match c { $($code => $name::$v,)* other => $name::Other(other) }
            }
            /// The controller's code.
            pub fn code(self) -> i32 {
                match self { $($name::$v => $code,)* $name::Other(c) => c }
            }
            /// The word the dashboard uses (`RUNNING`).
            pub fn name(self) -> &'static str {
                match self { $($name::$v => $word,)* $name::Other(_) => "UNKNOWN" }
            }
            /// From the dashboard's word.
            pub fn from_name(s: &str) -> Option<Self> {
                match s { $($word => Some($name::$v),)* _ => None }
            }
        }
        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                match self {
                    $name::Other(c) => write!(f, "UNKNOWN({c})"),
                    v => f.write_str(v.name()),
                }
            }
        }
    };
}

code_enum! {
    /// The controller's robot mode (RTDE `robot_mode`).
    RobotMode {
        /// No controller.
        NoController = -1, "NO_CONTROLLER";
        /// Disconnected.
        Disconnected = 0, "DISCONNECTED";
        /// Confirm safety.
        ConfirmSafety = 1, "CONFIRM_SAFETY";
        /// Booting.
        Booting = 2, "BOOTING";
        /// Power off.
        PowerOff = 3, "POWER_OFF";
        /// Power on.
        PowerOn = 4, "POWER_ON";
        /// Idle: powered, brakes engaged.
        Idle = 5, "IDLE";
        /// Backdrive.
        Backdrive = 6, "BACKDRIVE";
        /// Running: brakes released, ready to move.
        Running = 7, "RUNNING";
        /// Updating firmware.
        UpdatingFirmware = 8, "UPDATING_FIRMWARE";
    }
}

code_enum! {
    /// The controller's safety mode (RTDE `safety_mode`).
    SafetyMode {
        /// Normal.
        Normal = 1, "NORMAL";
        /// Reduced.
        Reduced = 2, "REDUCED";
        /// Protective stop.
        ProtectiveStop = 3, "PROTECTIVE_STOP";
        /// Recovery.
        Recovery = 4, "RECOVERY";
        /// Safeguard stop.
        SafeguardStop = 5, "SAFEGUARD_STOP";
        /// System emergency stop.
        SystemEmergencyStop = 6, "SYSTEM_EMERGENCY_STOP";
        /// Robot emergency stop.
        RobotEmergencyStop = 7, "ROBOT_EMERGENCY_STOP";
        /// Violation.
        Violation = 8, "VIOLATION";
        /// Fault.
        Fault = 9, "FAULT";
        /// Validate joint id.
        ValidateJointId = 10, "VALIDATE_JOINT_ID";
        /// Undefined.
        Undefined = 11, "UNDEFINED_SAFETY_MODE";
        /// Automatic-mode safeguard stop.
        AutomaticModeSafeguardStop = 12, "AUTOMATIC_MODE_SAFEGUARD_STOP";
        /// Three-position enabling stop.
        ThreePositionEnablingStop = 13, "SYSTEM_THREE_POSITION_ENABLING_STOP";
    }
}

code_enum! {
    /// The program runtime state (RTDE `runtime_state`).
    RuntimeState {
        /// Stopping.
        Stopping = 0, "STOPPING";
        /// Stopped.
        Stopped = 1, "STOPPED";
        /// Playing.
        Playing = 2, "PLAYING";
        /// Pausing.
        Pausing = 3, "PAUSING";
        /// Paused.
        Paused = 4, "PAUSED";
        /// Resuming.
        Resuming = 5, "RESUMING";
    }
}

/// `safety_status_bits`: protective stop.
pub const SAFETY_BIT_PROTECTIVE_STOP: u32 = 1 << 2;
/// `safety_status_bits`: system emergency stop.
pub const SAFETY_BIT_SYSTEM_EMERGENCY_STOP: u32 = 1 << 5;
/// `safety_status_bits`: robot emergency stop.
pub const SAFETY_BIT_ROBOT_EMERGENCY_STOP: u32 = 1 << 6;
/// `safety_status_bits`: emergency stop.
pub const SAFETY_BIT_EMERGENCY_STOP: u32 = 1 << 7;
/// `robot_status_bits`: power on.
pub const ROBOT_BIT_POWER_ON: u32 = 1;
/// `robot_status_bits`: program running.
pub const ROBOT_BIT_PROGRAM_RUNNING: u32 = 1 << 1;

/// Why the robot cannot be commanded. Each is a defined state with its own recovery.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RobotFault {
    /// No state for longer than the staleness limit, or the connection closed.
    Disconnected,
    /// An emergency stop is active (recover: release it, power on, brake release, restart).
    EmergencyStop,
    /// A protective stop is active (recover: dashboard `unlock protective stop`, restart).
    ProtectiveStop,
    /// Another safety mode than normal or reduced.
    Safety(SafetyMode),
    /// The arm is not in `RUNNING` mode (powered off, brakes engaged, …).
    NotRunning(RobotMode),
    /// Our control program is not running (stopped by the watchdog, a stop, or a fault).
    ProgramStopped,
}

impl std::fmt::Display for RobotFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RobotFault::Disconnected => f.write_str("robot connection lost or state stale"),
            RobotFault::EmergencyStop => f.write_str("emergency stop"),
            RobotFault::ProtectiveStop => f.write_str("protective stop"),
            RobotFault::Safety(m) => write!(f, "safety mode {m}"),
            RobotFault::NotRunning(m) => write!(f, "robot mode {m}, not RUNNING"),
            RobotFault::ProgramStopped => f.write_str("the control program is not running"),
        }
    }
}

/// Where a controller's `actual_TCP_force` comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ForceSource {
    /// CB3: estimated from the joint currents and the arm's model (no sensor; coarse, biased by
    /// payload and friction errors).
    JointCurrentEstimate,
    /// e-Series (and UR20/UR30): the 6-axis force/torque sensor in the tool flange (zeroed with
    /// `zero_ftsensor()`).
    FlangeSensor,
}

impl ForceSource {
    /// The source of a series' wrench.
    pub fn of(series: mocomp_kin::Series) -> Self {
        match series {
            mocomp_kin::Series::Cb3 => Self::JointCurrentEstimate,
            mocomp_kin::Series::ESeries => Self::FlangeSensor,
        }
    }

    /// Whether it is a measurement (a sensor), not an estimate.
    pub fn is_sensor(self) -> bool {
        self == Self::FlangeSensor
    }

    /// The force range of a model's flange sensor, N (per axis; UR's e-Series data sheets:
    /// UR3e 30, UR5e 50, UR10e 100, UR16e 160): a reading at its end is saturated and says only
    /// "at least this". `None` for a CB3's estimate, which has no range, and for the UR20/UR30,
    /// whose figure this project has not checked.
    pub fn range_n(model: mocomp_kin::Model) -> Option<f64> {
        use mocomp_kin::Model;
        match model {
            Model::Ur3e => Some(30.0),
            Model::Ur5e => Some(50.0),
            Model::Ur10e => Some(100.0),
            Model::Ur16e => Some(160.0),
            Model::Ur3 | Model::Ur5 | Model::Ur10 | Model::Ur20 | Model::Ur30 => None,
        }
    }
}

/// The robot's state at one controller cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotState {
    /// Controller time of the cycle (s since controller start).
    pub controller_s: f64,
    /// When we received it, on our clock (s).
    pub received_s: f64,
    /// Actual joint positions (rad).
    pub actual_q: [f64; 6],
    /// Actual joint velocities (rad/s).
    pub actual_qd: [f64; 6],
    /// Target joint positions (rad).
    pub target_q: [f64; 6],
    /// Actual TCP pose `base_from_tcp`.
    pub base_from_tcp: Pose,
    /// Robot mode.
    pub robot_mode: RobotMode,
    /// Safety mode.
    pub safety_mode: SafetyMode,
    /// Program runtime state.
    pub runtime_state: RuntimeState,
    /// `robot_status_bits`.
    pub robot_status_bits: u32,
    /// `safety_status_bits`.
    pub safety_status_bits: u32,
    /// Actual speed scaling (0..1).
    pub speed_scaling: f64,
    /// The control program's mode ([`crate::mode`]): 0 not running, 1 idle, …
    pub program_mode: i32,
    /// The sequence number of the newest command our program has taken.
    pub acked_seq: i32,
    /// The sequence number of the newest MOVEJ our program has completed.
    pub move_done_seq: i32,
    /// Whether our program (its protocol id) is running.
    pub program_ours: bool,
    /// Whether the connection is up.
    pub connected: bool,
    /// The wrench on the tool, `actual_TCP_force`: force (N) and torque (N·m) in the base
    /// frame. A CB3 estimates it from the joint currents; an e-Series measures it with the
    /// force/torque sensor in its tool flange ([`ForceSource::of`] says which).
    pub tcp_force: [f64; 6],
    /// `actual_digital_input_bits`: 0-7 standard, 8-15 configurable, 16-17 tool.
    pub digital_inputs: u64,
    /// `actual_digital_output_bits`, numbered alike.
    pub digital_outputs: u64,
}

impl RobotState {
    /// A healthy arm at rest at `q` (its flange at `base_from_tcp`), running mocomp's program,
    /// idle, at controller time `t_s`: where simulators and tests start.
    pub fn at_rest(
        t_s: f64,
        q: [f64; 6],
        base_from_tcp: mocomp_geom::nalgebra::Isometry3<f64>,
    ) -> Self {
        Self {
            controller_s: t_s,
            received_s: t_s,
            actual_q: q,
            actual_qd: [0.0; 6],
            target_q: q,
            base_from_tcp,
            robot_mode: RobotMode::Running,
            safety_mode: SafetyMode::Normal,
            runtime_state: RuntimeState::Playing,
            robot_status_bits: 0,
            safety_status_bits: 0,
            speed_scaling: 1.0,
            program_mode: crate::mode::IDLE,
            acked_seq: 0,
            move_done_seq: 0,
            program_ours: true,
            connected: true,
            tcp_force: [0.0; 6],
            digital_inputs: 0,
            digital_outputs: 0,
        }
    }

    /// The wrench on the tool in the TCP's frame (force N, torque N·m): what presses along the
    /// tool's axis is its z component.
    pub fn tcp_force_in_tool(&self) -> [f64; 6] {
        let tcp_from_base = self.base_from_tcp.rotation.inverse();
        let [fx, fy, fz, tx, ty, tz] = self.tcp_force;
        let f = tcp_from_base * mocomp_geom::nalgebra::Vector3::new(fx, fy, fz);
        let t = tcp_from_base * mocomp_geom::nalgebra::Vector3::new(tx, ty, tz);
        [f.x, f.y, f.z, t.x, t.y, t.z]
    }

    /// What forbids commanding the robot now, if anything (in order of severity).
    pub fn fault(&self) -> Option<RobotFault> {
        if !self.connected {
            return Some(RobotFault::Disconnected);
        }
        let bits = self.safety_status_bits;
        if bits
            & (SAFETY_BIT_EMERGENCY_STOP
                | SAFETY_BIT_ROBOT_EMERGENCY_STOP
                | SAFETY_BIT_SYSTEM_EMERGENCY_STOP)
            != 0
            || matches!(
                self.safety_mode,
                SafetyMode::RobotEmergencyStop | SafetyMode::SystemEmergencyStop
            )
        {
            return Some(RobotFault::EmergencyStop);
        }
        if bits & SAFETY_BIT_PROTECTIVE_STOP != 0 || self.safety_mode == SafetyMode::ProtectiveStop
        {
            return Some(RobotFault::ProtectiveStop);
        }
        if !matches!(self.safety_mode, SafetyMode::Normal | SafetyMode::Reduced) {
            return Some(RobotFault::Safety(self.safety_mode));
        }
        if self.robot_mode != RobotMode::Running {
            return Some(RobotFault::NotRunning(self.robot_mode));
        }
        if self.runtime_state != RuntimeState::Playing
            || !self.program_ours
            || self.program_mode <= 0
        {
            return Some(RobotFault::ProgramStopped);
        }
        None
    }
}

#[cfg(test)]
mod force_tests {
    use super::*;
    use mocomp_kin::{MODELS, Series};

    #[test]
    fn e_series_arms_measure_the_wrench_and_cb3_arms_estimate_it() {
        for spec in MODELS {
            let source = ForceSource::of(spec.series);
            assert_eq!(
                source.is_sensor(),
                spec.series == Series::ESeries,
                "{:?}",
                spec.model
            );
        }
        assert_eq!(
            ForceSource::of(Series::Cb3),
            ForceSource::JointCurrentEstimate
        );
    }

    #[test]
    fn only_a_sensor_has_a_range_and_a_bigger_arm_a_bigger_one() {
        for spec in MODELS {
            let range = ForceSource::range_n(spec.model);
            if spec.series == Series::Cb3 {
                assert_eq!(range, None, "{:?}", spec.model);
            }
        }
        let r = |m| ForceSource::range_n(m).unwrap();
        use mocomp_kin::Model;
        assert!(r(Model::Ur3e) < r(Model::Ur5e) && r(Model::Ur5e) < r(Model::Ur10e));
    }
}
