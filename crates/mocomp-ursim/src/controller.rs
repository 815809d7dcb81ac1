//! The simulated controller itself, without I/O: its state, safety modes and cycle here, and by
//! job in submodules: joint dynamics (`dynamics`), the RTDE variables and register store
//! (`variables`), the programs it runs natively, mocomp's and ur_rtde's (`programs`), and the
//! dashboard's commands (`dashboard`). One call to [`Controller::step`] is one controller cycle
//! (2 ms e-Series, 8 ms CB3).
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

use mocomp_geom::nalgebra::{Isometry3, Vector6};
use mocomp_geom::ur_pose_from_iso;
use mocomp_kin::{Arm, Model, ModelSpec};
use mocomp_robot::{RobotMode, RuntimeState, SafetyMode};
use mocomp_ur::codec::ControllerVersion;
use mocomp_ur::program::{self as mp, cmd as mcmd, mode as mmode};
use mocomp_ur::types::{DataType, REGISTERS, Value, input_type, output_type};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

mod dashboard;
mod dynamics;
mod io;
mod programs;
mod variables;

use dynamics::Motion;
pub use io::{Bank, Io};
use programs::{Program, Watchdog};
pub use programs::{ProgramKind, classify_program};
pub use variables::{InputSlot, OutputVar};
use variables::{NREG, Registers};

/// The world around the controller pressing on its tool: the wrench (N, N·m, base frame) at a
/// controller time (s) for the tool's pose `base_from_tcp`, called once per cycle (a contact
/// model, which may keep state: a damper, a sensor's noise).
pub type ToolLoadFn = dyn FnMut(f64, &Isometry3<f64>) -> [f64; 6] + Send;

/// A shared [`ToolLoadFn`].
#[derive(Clone)]
pub struct ToolLoad(pub Arc<Mutex<ToolLoadFn>>);

impl std::fmt::Debug for ToolLoad {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ToolLoad(..)")
    }
}

impl ToolLoad {
    /// A load from a function.
    pub fn new(f: impl FnMut(f64, &Isometry3<f64>) -> [f64; 6] + Send + 'static) -> Self {
        Self(Arc::new(Mutex::new(f)))
    }
}

/// UR's factory TCP force limit (the safety configuration's "Force", normal mode), N.
pub const DEFAULT_TCP_FORCE_LIMIT_N: f64 = 150.0;

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
    /// What presses on the tool (`None`: free space, or what [`Controller::set_tcp_force`] sets).
    pub tool_load: Option<ToolLoad>,
    /// The safety system's TCP force limit: above it the controller protective-stops, N.
    pub tcp_force_limit_n: f64,
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
            tool_load: None,
            tcp_force_limit_n: DEFAULT_TCP_FORCE_LIMIT_N,
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

/// One thing the simulator did or refused, with its controller time.
#[derive(Debug, Clone, PartialEq)]
pub struct SimEvent {
    /// Controller time, s.
    pub time_s: f64,
    /// What happened.
    pub text: String,
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
    /// The largest servo setpoint speed taken, as a share of its C204A3 limit, and when (s).
    setpoint_peak: (f64, f64),
    /// The wrench on the tool (N and N·m, base frame) as the world around the controller
    /// applies it (a contact; zero in free space).
    tcp_force: [f64; 6],
    /// What `zero_ftsensor()` took as the sensor's zero (e-Series): subtracted from what it
    /// reads.
    ft_offset: [f64; 6],
    /// Digital and analog I/O.
    io: Io,
    /// How many of the next mocomp programs find their client late: see
    /// [`Controller::hold_back_first_feeds`].
    late_first_feeds: u32,
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
            late_first_feeds: 0,
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
            setpoint_peak: (0.0, 0.0),
            tcp_force: [0.0; 6],
            ft_offset: [0.0; 6],
            io: Io::default(),
            config,
        }
    }

    /// Sets the wrench on the tool (N, N·m; base frame, as `actual_TCP_force` reports it): what
    /// the world around the controller applies (a contact model), from the next state sent.
    pub fn set_tcp_force(&mut self, wrench: [f64; 6]) {
        self.tcp_force = wrench;
    }

    /// The wrench on the tool as the force sensor reports it (`actual_TCP_force`): the applied
    /// wrench less the zero `zero_ftsensor()` took.
    pub fn tcp_force(&self) -> [f64; 6] {
        std::array::from_fn(|i| self.tcp_force[i] - self.ft_offset[i])
    }

    /// The I/O: outputs clients set, inputs the world drives.
    pub fn io(&self) -> &Io {
        &self.io
    }

    /// Drives digital input `bit` (0–7 standard, 8–15 configurable, 16–17 tool).
    pub fn set_digital_input(&mut self, bit: u32, on: bool) {
        self.io.set_digital_input(bit, on);
    }

    /// `zero_ftsensor()`: an e-Series takes the sensor's present reading as its zero (what the
    /// tool's own weight or a bias reads is no force). A CB3 has no sensor: recorded, no effect.
    pub fn zero_ftsensor(&mut self) {
        if self.spec.series == mocomp_kin::Series::ESeries {
            self.ft_offset = self.tcp_force;
            self.record_event("zero_ftsensor: force/torque sensor zeroed".into());
        } else {
            self.record_event(
                "zero_ftsensor on a CB3: no force/torque sensor to zero (its TCP force is an estimate)"
                    .into(),
            );
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

    /// The largest servo setpoint speed taken so far, as a share of the speed that makes it a
    /// jump (C204A3: `setpoint_speed_factor` × the joint's maximum; 1 or more stopped the arm),
    /// and the controller time it came, s: how close a client's setpoints came to a protective
    /// stop.
    pub fn setpoint_peak(&self) -> (f64, f64) {
        self.setpoint_peak
    }

    /// The newest events (at most 256 kept) and how many there were in all.
    pub fn events(&self) -> (Vec<SimEvent>, u64) {
        (self.events.iter().cloned().collect(), self.events_total)
    }

    /// The recent events' texts, oldest first (what a test looks through).
    pub fn event_texts(&self) -> Vec<String> {
        self.events.iter().map(|e| e.text.clone()).collect()
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

    // ---------------------------------------------------------------- one cycle

    /// Runs one controller cycle.
    pub fn step(&mut self) {
        self.tick += 1;
        self.time_s = self.tick as f64 * self.period;
        self.check_watchdog();
        self.run_program();
        self.integrate();
        self.check_limits();
        self.load_tool();
        self.finish_program_waits();
    }

    /// The wrench on the tool from the world's load, and the safety system's force limit on it.
    fn load_tool(&mut self) {
        if let Some(load) = &self.config.tool_load {
            let base_from_tcp = self.arm.fk(&self.q);
            let mut f = load
                .0
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner);
            self.tcp_force = f(self.time_s, &base_from_tcp);
        }
        let [fx, fy, fz, ..] = self.tcp_force;
        let force = (fx * fx + fy * fy + fz * fz).sqrt();
        if force > self.config.tcp_force_limit_n && self.safety_mode == SafetyMode::Normal {
            self.protective_stop(format!(
                "TCP force {force:.0} N over the safety limit {:.0} N",
                self.config.tcp_force_limit_n
            ));
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
        c.load_program(&mp::script(20.0, true));
        assert_eq!(c.runtime_state(), RuntimeState::Playing);
        c
    }

    #[test]
    fn free_drive_yields_to_a_push_and_ends_when_the_client_falls_silent() {
        let mut c = running(Model::Ur5e);
        let arm = Arm::new(Model::Ur5e);
        let p0 = arm.fk(&c.q()).translation.vector;
        c.apply_input(InputSlot::Int(24), Value::Int32(mcmd::FREEDRIVE));
        c.apply_input(InputSlot::Int(25), Value::Int32(1));
        step_fed(&mut c, 10);
        assert_eq!(c.output_int(24), mmode::FREEDRIVE);
        // No push: the arm stays.
        assert!((arm.fk(&c.q()).translation.vector - p0).norm() < 1e-12);
        // A hand pushes the tool along +x with 20 N for 1 s: it follows at about 0.1 m/s.
        c.set_tcp_force([20.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        step_fed(&mut c, 500);
        let moved = arm.fk(&c.q()).translation.vector - p0;
        assert!(moved.x > 0.09 && moved.x < 0.101, "{moved:?}");
        assert!(moved.y.abs() < 1e-3 && moved.z.abs() < 1e-3, "{moved:?}");
        // The client falls silent (no package): the watchdog stops the program, free-drive ends
        // and the arm stops although the hand still pushes.
        for _ in 0..500 {
            c.step();
        }
        assert_eq!(c.runtime_state(), RuntimeState::Stopped);
        let q = c.q();
        c.step();
        assert_eq!(c.q(), q, "still moving after the watchdog");
        assert!(
            c.events().0.iter().any(|e| e.text.contains("watchdog")),
            "{:?}",
            c.events().0
        );
    }

    #[test]
    fn leaving_free_drive_for_a_command_ends_it() {
        let mut c = running(Model::Ur5e);
        c.apply_input(InputSlot::Int(24), Value::Int32(mcmd::FREEDRIVE));
        c.apply_input(InputSlot::Int(25), Value::Int32(1));
        step_fed(&mut c, 5);
        let q = c.q();
        servo_inputs(&mut c, q, 2);
        step_fed(&mut c, 5);
        assert_eq!(c.output_int(24), mmode::SERVO);
        assert!(c.events().0.iter().any(|e| e.text == "free-drive ended"));
    }

    #[test]
    fn movel_keeps_the_tool_on_the_straight_line_and_stops_on_the_target() {
        let mut c = Controller::new(ControllerConfig::new(Model::Ur5e));
        let arm = Arm::new(Model::Ur5e);
        let start = arm.fk(&c.q());
        let goal = Isometry3::translation(0.06, -0.02, 0.03) * start;
        assert!(c.start_linear(goal, 0.1, 0.5));
        let line = goal.translation.vector - start.translation.vector;
        let mut steps = 0;
        while !matches!(c.motion, Motion::Idle) {
            c.step();
            steps += 1;
            assert!(steps < 5_000, "movel did not end");
            let p = arm.fk(&c.q()).translation.vector - start.translation.vector;
            let off = (p - line * (p.dot(&line) / line.norm_squared())).norm();
            assert!(off < 1e-9, "{off} m off the line at step {steps}");
            // Never faster than asked (the tool speed along the line).
            let v = arm.jacobian(&c.q()) * Vector6::from_column_slice(&c.qd);
            let speed = v.fixed_rows::<3>(0).norm();
            assert!(speed < 0.1 + 1e-3, "{speed} m/s");
        }
        let end = arm.fk(&c.q());
        assert!((end.translation.vector - goal.translation.vector).norm() < 1e-9);
        // At 0.1 m/s with 0.5 m/s² ramps: distance / v + v / a.
        let t = steps as f64 * c.period_s();
        let dist = line.norm();
        assert!(
            (t - (dist / 0.1 + 0.1 / 0.5)).abs() < 0.01,
            "{t} s for {dist} m"
        );
        // Out of reach: refused, nothing moves.
        let q = c.q();
        assert!(!c.start_linear(Isometry3::translation(5.0, 0.0, 0.0), 0.1, 0.5));
        assert_eq!(c.q(), q);
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
        // Half the jump's speed (1.2 × π rad/s on the elbow) is taken, and its share kept.
        q[2] += 0.5 * 1.2 * std::f64::consts::PI * 0.002;
        servo_inputs(&mut c, q, 1);
        c.step();
        assert_eq!(c.safety_mode(), SafetyMode::Normal);
        let (share, at) = c.setpoint_peak();
        assert!((share - 0.5).abs() < 1e-9 && at > 0.0, "{share} at {at}");
        q[2] += 0.1; // 0.1 rad in 2 ms = 50 rad/s
        servo_inputs(&mut c, q, 2);
        c.step();
        assert!(c.setpoint_peak().0 > 10.0, "{:?}", c.setpoint_peak());
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

    /// The simulator's own reader late with the client's packages waiting: the watchdog says it
    /// is due and is deferred, never for a client that is silent.
    #[test]
    fn input_waiting_unread_defers_the_watchdog_and_silence_still_stops_it() {
        let mut c = running(Model::Ur3e); // 20 Hz: 50 ms
        let q = c.q();
        servo_inputs(&mut c, q, 1);
        c.step();
        let mut due_after = None;
        for k in 1..=40 {
            if c.watchdog_due() {
                due_after.get_or_insert(k);
                c.note_unread_input();
                assert!(!c.watchdog_due());
            }
            c.step();
            assert_eq!(c.runtime_state(), RuntimeState::Playing, "cycle {k}");
        }
        // Due exactly when a silent client is stopped: 25 cycles on (52 ms after the input came,
        // a cycle before the first of them).
        assert_eq!(due_after, Some(25));
        // The reader took the packages; the client then falls silent: stopped 50 ms on.
        servo_inputs(&mut c, q, 2);
        c.step();
        let mut stopped_after = None;
        for k in 1..=40 {
            c.step();
            if c.runtime_state() == RuntimeState::Stopped {
                stopped_after = Some(k);
                break;
            }
        }
        assert_eq!(stopped_after, Some(25));
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
        c.load_program(&mp::script(20.0, true));
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
        c.load_program(&mp::script(20.0, true));
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
            classify_program(&mp::script(12.5, true)),
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

    #[test]
    fn the_tools_load_is_read_each_cycle_and_a_force_over_the_limit_protective_stops() {
        let mut cfg = ControllerConfig::new(Model::Ur5e);
        // A contact that presses harder every cycle: 1 N per controller millisecond.
        cfg.tool_load = Some(ToolLoad::new(|t, base_from_tcp| {
            let up = base_from_tcp.rotation * -mocomp_geom::nalgebra::Vector3::z();
            let f = up * (t * 1000.0);
            [f.x, f.y, f.z, 0.0, 0.0, 0.0]
        }));
        let mut c = Controller::new(cfg);
        for _ in 0..25 {
            c.step();
        }
        // 25 cycles of 2 ms: 50 N, served as actual_TCP_force, no stop yet.
        let f = c.tcp_force();
        let n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt();
        assert!((n - 50.0).abs() < 1e-9, "{f:?}");
        assert_eq!(c.safety_mode(), SafetyMode::Normal);
        assert_eq!(c.output(OutputVar::TcpForce), Value::Vector6d(f));
        // Past 150 N (75 cycles): the safety system stops the arm, once.
        for _ in 0..60 {
            c.step();
        }
        assert_eq!(c.safety_mode(), SafetyMode::ProtectiveStop);
        assert_eq!(c.protective_stops(), 1);
    }
}
