//! [`UrRobot`]: the [`Robot`] trait over RTDE, with mocomp's resident control program.
//!
//! Connecting: RTDE handshake (protocol 2, fallback 1) and controller version (which fixes the
//! rate: 125 Hz CB3, 500 Hz e-Series), the state output recipe and the command input recipe,
//! start; the dashboard checks (remote control on 5.6+, robot mode, safety mode); the program
//! upload to the script port; then a thread receives every state package and publishes the
//! newest one in a lock-free cell. Commands are written from the caller's thread straight to the
//! socket (one small package each, no allocation, no lock).

use crate::codec::{ControllerVersion, Recipe};
use crate::connection::{RTDE_PORT, RtdeConnection};
use crate::dashboard::{DASHBOARD_PORT, Dashboard};
use crate::error::UrError;
use crate::error::range;
use crate::program::{self, INPUT_NAMES, OUTPUT_REGISTER_NAMES, PROTOCOL_ID, cmd};
use crate::recovery::{self, Recovered, RecoveryError, Step};
use crate::types::Value;
use mocomp_geom::{Clock, SeqLock, iso_from_ur_pose, ur_pose_from_iso};
use mocomp_robot::{Robot, RobotError, ServoParams};
use mocomp_robot::{RobotFault, RobotMode, RobotState, RuntimeState, SafetyMode};
use std::io::{Read, Write};
use std::net::{IpAddr, SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The real-time script port the program is uploaded to.
pub const SCRIPT_PORT: u16 = 30003;

/// The largest joint speed a command may ask for, rad/s (ur_rtde's client-side limit, 3.14).
#[allow(clippy::approx_constant)] // 3.14 is the published limit, not π
pub const MAX_JOINT_SPEED: f64 = 3.14;

/// The output variables of the state recipe, in order.
pub const STATE_NAMES: [&str; 19] = [
    "timestamp",
    "actual_q",
    "actual_qd",
    "target_q",
    "actual_TCP_pose",
    "robot_mode",
    "safety_mode",
    "runtime_state",
    "robot_status_bits",
    "safety_status_bits",
    "speed_scaling",
    OUTPUT_REGISTER_NAMES[0],
    OUTPUT_REGISTER_NAMES[1],
    OUTPUT_REGISTER_NAMES[2],
    OUTPUT_REGISTER_NAMES[3],
    "input_int_register_25",
    // The wrench on the tool (CB3: estimated from the joint currents; e-Series: from the tool
    // flange's force/torque sensor), base frame.
    "actual_TCP_force",
    // Bits 0-7 standard, 8-15 configurable, 16-17 tool (UR's RTDE guide): the stimulator's
    // pulse comes in on an input; the on-target gate goes out on an output.
    "actual_digital_input_bits",
    "actual_digital_output_bits",
];

/// The input recipe that sets digital outputs: only the bits in a mask change, so setting one
/// output leaves the others (and the program's) as they are.
pub const IO_INPUT_NAMES: [&str; 4] = [
    "standard_digital_output_mask",
    "standard_digital_output",
    "configurable_digital_output_mask",
    "configurable_digital_output",
];

/// How to reach and run the robot.
#[derive(Debug, Clone)]
pub struct UrConfig {
    /// Controller address.
    pub host: IpAddr,
    /// RTDE port (30004).
    pub rtde_port: u16,
    /// Dashboard port (29999).
    pub dashboard_port: u16,
    /// Script port the program is uploaded to (30003).
    pub script_port: u16,
    /// Connect and reply timeout.
    pub timeout: Duration,
    /// RTDE output frequency, Hz (`None`: the controller's rate).
    pub frequency: Option<f64>,
    /// The program's watchdog: it stops when no command package arrives for `1 / watchdog_hz`.
    pub watchdog_hz: f64,
    /// Query the dashboard before uploading (remote control, robot and safety mode).
    pub check_dashboard: bool,
    /// Power on and release the brakes through the dashboard when the arm is not running.
    pub power_on: bool,
    /// How long to wait for the program to report itself running.
    pub program_start_timeout: Duration,
}

impl UrConfig {
    /// Defaults for a controller at `host` on the standard ports.
    pub fn new(host: IpAddr) -> Self {
        Self {
            host,
            rtde_port: RTDE_PORT,
            dashboard_port: DASHBOARD_PORT,
            script_port: SCRIPT_PORT,
            timeout: Duration::from_secs(2),
            frequency: None,
            watchdog_hz: 20.0,
            check_dashboard: true,
            power_on: false,
            program_start_timeout: Duration::from_secs(5),
        }
    }
}

const WORDS: usize = 45;

struct Shared {
    cell: SeqLock<WORDS>,
    stop: AtomicBool,
    last_error: Mutex<Option<String>>,
    /// The thread blocked in [`Robot::wait_for_state`], woken after each state is published.
    /// Set once per waiting thread; the state thread only ever `try_lock`s it, so it never waits.
    waiter: Mutex<Option<std::thread::Thread>>,
}

/// A connected UR robot running mocomp's control program.
pub struct UrRobot {
    config: UrConfig,
    clock: Arc<dyn Clock>,
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    writer: TcpStream,
    recipe: Recipe,
    /// The [`IO_INPUT_NAMES`] recipe.
    io_recipe: Recipe,
    values: [Value; 11],
    buf: Vec<u8>,
    seq: i32,
    version: ControllerVersion,
    period_s: f64,
    waiter: Option<std::thread::ThreadId>,
}

impl std::fmt::Debug for UrRobot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UrRobot")
            .field("host", &self.config.host)
            .field("version", &self.version)
            .field("seq", &self.seq)
            .finish()
    }
}

fn encode_state(s: &RobotState) -> [f64; WORDS] {
    let mut w = [0.0; WORDS];
    w[0] = s.controller_s;
    w[1] = s.received_s;
    w[2..8].copy_from_slice(&s.actual_q);
    w[8..14].copy_from_slice(&s.actual_qd);
    w[14..20].copy_from_slice(&s.target_q);
    w[20..26].copy_from_slice(&ur_pose_from_iso(&s.base_from_tcp));
    w[26] = f64::from(s.robot_mode.code());
    w[27] = f64::from(s.safety_mode.code());
    w[28] = f64::from(s.runtime_state.code());
    w[29] = f64::from(s.robot_status_bits);
    w[30] = f64::from(s.safety_status_bits);
    w[31] = s.speed_scaling;
    w[32] = f64::from(s.program_mode);
    w[33] = f64::from(s.acked_seq);
    w[34] = f64::from(s.move_done_seq);
    w[35] = f64::from(u8::from(s.program_ours));
    w[36] = f64::from(u8::from(s.connected));
    w[37..43].copy_from_slice(&s.tcp_force);
    // Exact: the bits in use (18) are far below f64's 53.
    w[43] = s.digital_inputs as f64;
    w[44] = s.digital_outputs as f64;
    w
}

fn six(w: &[f64]) -> [f64; 6] {
    let mut a = [0.0; 6];
    a.copy_from_slice(&w[..6]);
    a
}

fn decode_state(w: &[f64; WORDS]) -> RobotState {
    RobotState {
        controller_s: w[0],
        received_s: w[1],
        actual_q: six(&w[2..8]),
        actual_qd: six(&w[8..14]),
        target_q: six(&w[14..20]),
        base_from_tcp: iso_from_ur_pose(&six(&w[20..26])).unwrap_or_default(),
        robot_mode: RobotMode::from_code(w[26] as i32),
        safety_mode: SafetyMode::from_code(w[27] as i32),
        runtime_state: RuntimeState::from_code(w[28] as i32),
        robot_status_bits: w[29] as u32,
        safety_status_bits: w[30] as u32,
        speed_scaling: w[31],
        program_mode: w[32] as i32,
        acked_seq: w[33] as i32,
        move_done_seq: w[34] as i32,
        program_ours: w[35] != 0.0,
        connected: w[36] != 0.0,
        tcp_force: six(&w[37..43]),
        digital_inputs: w[43] as u64,
        digital_outputs: w[44] as u64,
    }
}

/// Builds a state from one package of the [`STATE_NAMES`] recipe.
fn state_from_values(v: &[Value], received_s: f64) -> Option<RobotState> {
    let f = |i: usize| v.get(i).and_then(Value::as_f64);
    let v6 = |i: usize| v.get(i).and_then(Value::as_vec6);
    let pose = v6(4)?;
    Some(RobotState {
        controller_s: f(0)?,
        received_s,
        actual_q: v6(1)?,
        actual_qd: v6(2)?,
        target_q: v6(3)?,
        base_from_tcp: iso_from_ur_pose(&pose).ok()?,
        robot_mode: RobotMode::from_code(f(5)? as i32),
        safety_mode: SafetyMode::from_code(f(6)? as i32),
        runtime_state: RuntimeState::from_code(f(7)? as i32),
        robot_status_bits: f(8)? as u32,
        safety_status_bits: f(9)? as u32,
        speed_scaling: f(10)?,
        program_mode: f(11)? as i32,
        acked_seq: f(12)? as i32,
        program_ours: f(13)? as i32 == PROTOCOL_ID,
        move_done_seq: f(14)? as i32,
        connected: true,
        tcp_force: v6(16)?,
        digital_inputs: bits(v.get(17)?)?,
        digital_outputs: bits(v.get(18)?)?,
    })
}

/// Fastest joint speed a state may report, rad/s: above any UR's (UR3 wrist: 2π rad/s), so a
/// larger one is a corrupted package, not motion.
const PLAUSIBLE_SPEED: f64 = 10.0;

/// Why `s` cannot be a state the controller sent after `prev` (the one before it on this
/// connection), naming the field: RTDE has no checksum, and bytes corrupted past TCP's own check
/// (a faulty switch, a bad proxy, a bug) decode into numbers. A non-finite value, a joint
/// speed no arm has, the controller's clock going back, or a joint that moved further than its
/// speed allows since the last package.
pub fn implausible(s: &RobotState, prev: Option<&RobotState>) -> Option<String> {
    let finite6 = |v: &[f64; 6]| v.iter().all(|x| x.is_finite());
    for (name, v) in [
        ("actual_q", &s.actual_q),
        ("actual_qd", &s.actual_qd),
        ("target_q", &s.target_q),
        ("actual_TCP_force", &s.tcp_force),
    ] {
        if !finite6(v) {
            return Some(format!("{name} {v:?} is not finite"));
        }
    }
    if !s.controller_s.is_finite() || s.controller_s < 0.0 {
        return Some(format!("timestamp {} is not a time", s.controller_s));
    }
    if let Some(j) = (0..6).find(|&j| s.actual_qd[j].abs() > PLAUSIBLE_SPEED) {
        return Some(format!(
            "actual_qd[{j}] = {} rad/s: faster than any UR joint",
            s.actual_qd[j]
        ));
    }
    if !(0.0..=1.5).contains(&s.speed_scaling) {
        return Some(format!(
            "speed_scaling {} is outside [0, 1]",
            s.speed_scaling
        ));
    }
    if let Some(p) = prev {
        let dt = s.controller_s - p.controller_s;
        if dt < 0.0 {
            return Some(format!(
                "timestamp {} went back from {}",
                s.controller_s, p.controller_s
            ));
        }
        // Over the controller time that passed, at the fastest plausible speed, and a
        // millimetre-scale allowance for the encoders.
        let reach = PLAUSIBLE_SPEED * dt + 1e-3;
        for (name, a, b) in [
            ("actual_q", &s.actual_q, &p.actual_q),
            ("target_q", &s.target_q, &p.target_q),
        ] {
            if let Some(j) = (0..6).find(|&j| (a[j] - b[j]).abs() > reach) {
                return Some(format!(
                    "{name}[{j}] jumped from {} to {} in {dt} s",
                    b[j], a[j]
                ));
            }
        }
    }
    None
}

fn bits(v: &Value) -> Option<u64> {
    match *v {
        Value::Uint64(b) => Some(b),
        _ => None,
    }
}

impl UrRobot {
    /// Connects, checks, uploads the control program and waits until it runs.
    pub fn connect(config: UrConfig, clock: Arc<dyn Clock>) -> Result<UrRobot, UrError> {
        let rtde_addr = SocketAddr::new(config.host, config.rtde_port);
        let mut conn = RtdeConnection::connect(rtde_addr, config.timeout)?;
        conn.negotiate()?;
        let version = conn.controller_version()?;
        let max = version.max_frequency();
        let frequency = config.frequency.unwrap_or(max);
        range("RTDE frequency", frequency, 1.0, max)?;
        let out = conn.setup_outputs(frequency, &STATE_NAMES)?;
        let recipe = conn.setup_inputs(&INPUT_NAMES)?;
        let io_recipe = conn.setup_inputs(&IO_INPUT_NAMES)?;
        conn.start()?;
        let mut values = Vec::with_capacity(STATE_NAMES.len());
        conn.receive(&out, &mut values, true)?;
        let first = state_from_values(&values, clock.now_s()).ok_or(UrError::Refused {
            what: "a state package of the requested layout".into(),
        })?;
        let start_seq = values
            .get(15)
            .and_then(Value::as_f64)
            .map_or(0, |x| x as i32);

        if config.check_dashboard {
            check_dashboard(&config, version)?;
        }

        let writer = conn.try_clone_stream()?;
        let shared = Arc::new(Shared {
            cell: SeqLock::new(),
            stop: AtomicBool::new(false),
            last_error: Mutex::new(None),
            waiter: Mutex::new(None),
        });
        shared.cell.publish(&encode_state(&first));
        let thread = {
            let shared = Arc::clone(&shared);
            let clock = Arc::clone(&clock);
            std::thread::Builder::new()
                .name("ur-state".into())
                .spawn(move || {
                    let watch = mocomp_geom::Watch::new();
                    let done = watch.run("ur-state", || {
                        state_thread(conn, out, values, Arc::clone(&shared), clock);
                    });
                    if done.is_none() {
                        // The reader met a bug, not a fault of the stream: the connection is
                        // given up as if lost (the loop stops the arm), named for the summary;
                        // a re-arm connects afresh.
                        record(&shared, watch.last().unwrap_or_default());
                        if let Some((_, w)) = shared.cell.read() {
                            let mut s = decode_state(&w);
                            s.connected = false;
                            shared.cell.publish(&encode_state(&s));
                        }
                        wake(&shared);
                    }
                })
                .map_err(|e| UrError::io("starting the state thread", e))?
        };
        let mut robot = UrRobot {
            period_s: if version.major < 5 { 0.008 } else { 0.002 },
            config,
            clock,
            shared,
            thread: Some(thread),
            writer,
            recipe,
            io_recipe,
            values: [Value::Int32(0); 11],
            buf: Vec::with_capacity(128),
            seq: start_seq,
            version,
            waiter: None,
        };
        robot.values[0] = Value::Int32(cmd::NONE);
        robot.values[1] = Value::Int32(start_seq);
        for v in &mut robot.values[2..] {
            *v = Value::Double(0.0);
        }
        robot.upload_and_wait()?;
        Ok(robot)
    }

    /// The controller's software version.
    pub fn controller_version(&self) -> ControllerVersion {
        self.version
    }

    /// The configuration.
    pub fn config(&self) -> &UrConfig {
        &self.config
    }

    /// The newest state's fault, including staleness: no state for `stale_s` seconds (on the
    /// robot's clock) is [`RobotFault::Disconnected`].
    pub fn fault_at(&self, now_s: f64, stale_s: f64) -> Option<RobotFault> {
        match self.state() {
            None => Some(RobotFault::Disconnected),
            Some(s) if now_s - s.received_s > stale_s => Some(RobotFault::Disconnected),
            Some(s) => s.fault(),
        }
    }

    /// Why the state thread ended, if it did.
    pub fn last_error(&self) -> Option<String> {
        self.shared.last_error.lock().ok().and_then(|g| g.clone())
    }

    /// Uploads the control program again and waits for it (after a protective stop was
    /// unlocked, or the watchdog stopped it).
    pub fn restart_program(&mut self) -> Result<(), UrError> {
        self.upload_and_wait()
    }

    /// Unlocks a protective stop through the dashboard and restarts the program.
    pub fn recover_protective_stop(&mut self) -> Result<(), UrError> {
        let mut d = Dashboard::connect(
            SocketAddr::new(self.config.host, self.config.dashboard_port),
            self.config.timeout,
        )?;
        d.unlock_protective_stop()?;
        self.wait_for("safety mode NORMAL after unlocking", |s| {
            s.safety_mode == SafetyMode::Normal && s.robot_mode == RobotMode::Running
        })?;
        self.restart_program()
    }

    /// The operator's re-arm after the controller stopped the arm: does what
    /// [`crate::recovery::plan`] says from the newest state (`stale_s`: a state older than this,
    /// on the robot's clock at `now_s`, means the stream is dead), and says what it did. A step
    /// software may not take is refused, with what the operator must do.
    pub fn recover(&mut self, now_s: f64, stale_s: f64) -> Result<Recovered, RecoveryError> {
        let state = self.state();
        let alive = self.thread.as_ref().is_some_and(|t| !t.is_finished())
            && state.is_some_and(|s| now_s - s.received_s <= stale_s);
        let step = recovery::plan(state.as_ref(), alive);
        let done = match step {
            Step::Nothing => Ok(Recovered::Healthy),
            Step::Reconnect => self.reconnect().map(|()| Recovered::Reconnected),
            Step::UnlockProtectiveStop => self
                .recover_protective_stop()
                .map(|()| Recovered::ProtectiveStopUnlocked),
            Step::RestartProgram => self.restart_program().map(|()| Recovered::ProgramRestarted),
            Step::Refuse(r) => return Err(RecoveryError::Refused(r)),
        };
        done.map_err(|source| RecoveryError::Failed { step, source })
    }

    /// Closes this connection and connects again with the same configuration.
    pub fn reconnect(&mut self) -> Result<(), UrError> {
        let fresh = UrRobot::connect(self.config.clone(), Arc::clone(&self.clock))?;
        *self = fresh;
        Ok(())
    }

    /// Runs `f` on another thread while this one keeps the program's watchdog fed, and returns
    /// its result. Once connected, the program stops when no package arrives for
    /// `1 / watchdog_hz` (50 ms by default); work between commands that may take longer (planning
    /// poses, loading files, a slow machine) goes through here instead of starving it.
    ///
    /// The work runs under normal time-sharing on any CPU, whatever the caller's scheduling: a
    /// thread inherits its creator's SCHED_FIFO priority and CPU, and a real-time caller pinned
    /// to one CPU could then not preempt its own busy worker (equal FIFO priorities take turns
    /// only when one blocks), so the watchdog would starve exactly when this is used.
    pub fn keep_alive_while<T: Send>(
        &mut self,
        f: impl FnOnce() -> T + Send,
    ) -> Result<T, UrError> {
        let interval = Duration::from_secs_f64((0.25 / self.config.watchdog_hz).min(0.01));
        std::thread::scope(|s| {
            let work = s.spawn(|| {
                // Best effort: a caller that is not real-time has nothing to give up.
                mocomp_rt::set_normal().ok();
                mocomp_rt::unpin().ok();
                f()
            });
            while !work.is_finished() {
                self.send()?;
                std::thread::sleep(interval);
            }
            // A panic in `f` is a bug in the caller's code: carry it on as one.
            Ok(work.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
        })
    }

    /// Ends the program (EXIT after stopping) and closes the connection.
    pub fn close(mut self) -> Result<(), UrError> {
        self.command(cmd::EXIT, [0.0; 6], [4.0, 0.0, 0.0]).map(drop)
    }

    /// Zeroes the force/torque sensor (`zero_ftsensor()` in the control program): its present
    /// reading becomes zero. Call it with the tool touching nothing: a contact present now would
    /// read as no force afterwards. A CB3 has no sensor (its TCP force is an estimate), so it is
    /// refused there. Returns the command's sequence number.
    pub fn zero_force_sensor(&mut self) -> Result<i32, UrError> {
        if self.version.major < 5 {
            return Err(UrError::Refused {
                what: "zeroing the force sensor: a CB3 has none (its TCP force is an estimate \
                       from the joint currents)"
                    .into(),
            });
        }
        self.command(cmd::ZERO_FT, [0.0; 6], [0.0; 3])
    }

    /// Free-drive (`freedrive_mode()`): the arm yields to a hand that moves it, for as long as
    /// this command is sent. Send it each cycle (or [`Robot::keep_alive`], which repeats it):
    /// when the client falls silent the control program's watchdog stops the program and
    /// free-drive with it, so the client's keep-alive is free-drive's dead-man switch. Any other
    /// command ends it. Refused while the robot reports a fault. Returns the sequence number.
    pub fn freedrive(&mut self) -> Result<i32, UrError> {
        self.check_motion_allowed()?;
        self.command(cmd::FREEDRIVE, [0.0; 6], [0.0; 3])
    }

    /// Uploads the control program and waits for it to run, feeding its watchdog. A program
    /// whose watchdog stopped it before this client's first commands reached it (a busy PC held
    /// the client back past the watchdog's 50 ms between the upload and the first feed: seen
    /// with two test suites and stress-ng on two cores) is uploaded again, twice at most: the
    /// robot is healthy and nothing has moved. Any other failure is the caller's.
    fn upload_and_wait(&mut self) -> Result<(), UrError> {
        let mut again = 0;
        loop {
            match self.upload_and_wait_once() {
                Err(UrError::Timeout { .. }) if again < 2 && self.program_stopped_by_itself() => {
                    again += 1;
                }
                done => return done,
            }
        }
    }

    /// The robot is running and healthy but no program is: one stopped by itself.
    fn program_stopped_by_itself(&self) -> bool {
        self.state().is_some_and(|s| {
            s.connected
                && s.robot_mode == RobotMode::Running
                && matches!(s.safety_mode, SafetyMode::Normal | SafetyMode::Reduced)
                && s.runtime_state == RuntimeState::Stopped
        })
    }

    fn upload_and_wait_once(&mut self) -> Result<(), UrError> {
        // A program of ours still running (a client before this one gone, its watchdog not yet
        // run out) acknowledges this client's commands just as the new one will: it is ended
        // first, so that only the program uploaded now can satisfy the wait below.
        let running = |s: &RobotState| s.program_ours && s.runtime_state == RuntimeState::Playing;
        if self.state().is_some_and(|s| running(&s)) {
            self.command(cmd::EXIT, [0.0; 6], [0.0; 3])?;
            self.wait_for("the control program left running to end", |s| !running(s))?;
        }
        // Clear the command registers first: they keep their values, and a new program must not
        // resume the last servo target or speed (ur_rtde sends a clear command for the same
        // reason).
        self.command(cmd::NONE, [0.0; 6], [0.0; 3])?;
        let addr = SocketAddr::new(self.config.host, self.config.script_port);
        let text = program::script(self.config.watchdog_hz, self.version.major >= 5);
        let mut s = TcpStream::connect_timeout(&addr, self.config.timeout)
            .map_err(|e| UrError::io(format!("connecting to the script port {addr}"), e))?;
        s.write_all(text.as_bytes())
            .map_err(|e| UrError::io(format!("uploading the control program to {addr}"), e))?;
        // The script manual asks clients to read before closing, or the data may be discarded.
        s.shutdown(std::net::Shutdown::Write).ok();
        // Briefly: the program may already run, and its watchdog is fed only once this returns.
        s.set_read_timeout(Some(Duration::from_millis(10))).ok();
        let mut sink = [0u8; 256];
        let _ = s.read(&mut sink);
        let seq = self.seq;
        self.wait_for("the control program to start", |st| {
            st.program_ours
                && st.program_mode > 0
                && st.runtime_state == RuntimeState::Playing
                && st.acked_seq == seq
        })
    }

    /// Waits (keeping the watchdog fed) until the state satisfies `ok`.
    fn wait_for(&mut self, what: &str, ok: impl Fn(&RobotState) -> bool) -> Result<(), UrError> {
        let start = Instant::now();
        let limit = self.config.program_start_timeout;
        loop {
            if let Some(s) = self.state() {
                if ok(&s) {
                    return Ok(());
                }
                if !s.connected {
                    return Err(UrError::Closed {
                        what: format!(
                            "RTDE at {} ({})",
                            self.config.host,
                            self.last_error().unwrap_or_default()
                        ),
                    });
                }
            }
            if start.elapsed() > limit {
                let detail = self.state().map_or("no state".to_string(), |s| {
                    format!(
                        "robot mode {}, safety mode {}, runtime state {}, program mode {}",
                        s.robot_mode, s.safety_mode, s.runtime_state, s.program_mode
                    )
                });
                return Err(UrError::Timeout {
                    what: format!("{what} ({detail})"),
                    ms: limit.as_millis(),
                });
            }
            self.send()?;
            std::thread::sleep(Duration::from_secs_f64(self.period_s.max(0.002)));
        }
    }

    fn command(&mut self, code: i32, v: [f64; 6], extra: [f64; 3]) -> Result<i32, UrError> {
        self.seq = self.seq.wrapping_add(1);
        self.values[0] = Value::Int32(code);
        self.values[1] = Value::Int32(self.seq);
        for (slot, x) in self.values[2..8].iter_mut().zip(v) {
            *slot = Value::Double(x);
        }
        for (slot, x) in self.values[8..11].iter_mut().zip(extra) {
            *slot = Value::Double(x);
        }
        self.send()?;
        Ok(self.seq)
    }

    /// Sets digital output `bit` (0-7 standard, 8-15 configurable) high or low through RTDE,
    /// leaving every other output as it is. Allowed in any robot state (it moves nothing); a
    /// safety configuration that gives the output another function overrides it on the robot.
    pub fn set_digital_output(&mut self, bit: u32, on: bool) -> Result<(), UrError> {
        if bit > 15 {
            return Err(UrError::Refused {
                what: format!("digital output {bit}: outputs 0-7 are standard, 8-15 configurable"),
            });
        }
        let (mask, level) = (1u8 << (bit % 8), if on { 1u8 << (bit % 8) } else { 0 });
        let values = if bit < 8 {
            [
                Value::Uint8(mask),
                Value::Uint8(level),
                Value::Uint8(0),
                Value::Uint8(0),
            ]
        } else {
            [
                Value::Uint8(0),
                Value::Uint8(0),
                Value::Uint8(mask),
                Value::Uint8(level),
            ]
        };
        self.buf.clear();
        self.io_recipe
            .encode_input_package(&values, &mut self.buf)
            .map_err(|e| UrError::Rtde {
                context: "encoding a digital output".into(),
                cause: e,
            })?;
        self.writer.write_all(&self.buf).map_err(|e| {
            UrError::io(
                format!("setting digital output {bit} on {}", self.config.host),
                e,
            )
        })
    }

    fn send(&mut self) -> Result<(), UrError> {
        self.buf.clear();
        self.recipe
            .encode_input_package(&self.values, &mut self.buf)
            .map_err(|e| UrError::Rtde {
                context: "encoding a command".into(),
                cause: e,
            })?;
        self.writer
            .write_all(&self.buf)
            .map_err(|e| UrError::io(format!("sending a command to {}", self.config.host), e))
    }

    fn check_motion_allowed(&self) -> Result<(), UrError> {
        match self.state().and_then(|s| s.fault()) {
            Some(f) => Err(RobotError::Fault(f).into()),
            None => Ok(()),
        }
    }
}

fn finite6(field: &'static str, v: &[f64; 6]) -> Result<(), UrError> {
    for x in v {
        range(field, *x, -1e6, 1e6)?;
    }
    Ok(())
}

impl Robot for UrRobot {
    fn state(&self) -> Option<RobotState> {
        self.shared.cell.read().map(|(_, w)| decode_state(&w))
    }

    fn state_count(&self) -> u64 {
        self.shared.cell.version()
    }

    fn wait_for_state(&mut self, seen: u64, timeout: Duration) -> u64 {
        let me = std::thread::current();
        if self.waiter != Some(me.id()) {
            // Once per waiting thread, never per cycle.
            if let Ok(mut w) = self.shared.waiter.lock() {
                *w = Some(me.clone());
                self.waiter = Some(me.id());
            }
        }
        let end = Instant::now() + timeout;
        loop {
            let n = self.state_count();
            if n != seen {
                return n;
            }
            let now = Instant::now();
            if now >= end {
                return n;
            }
            // An unpark between the check above and this park makes it return at once.
            std::thread::park_timeout(end - now);
        }
    }

    fn period_s(&self) -> f64 {
        self.period_s
    }

    fn servo(&mut self, q: &[f64; 6], p: &ServoParams) -> Result<i32, RobotError> {
        p.validate()?;
        finite6("servo target", q)?;
        self.check_motion_allowed()?;
        Ok(self.command(cmd::SERVOJ, *q, [p.time_s, p.lookahead_s, p.gain])?)
    }

    fn move_joints(&mut self, q: &[f64; 6], speed: f64, accel: f64) -> Result<i32, RobotError> {
        finite6("move target", q)?;
        range("move speed", speed, 1e-6, MAX_JOINT_SPEED)?;
        range("move acceleration", accel, 1e-6, 40.0)?;
        self.check_motion_allowed()?;
        Ok(self.command(cmd::MOVEJ, *q, [speed, accel, 0.0])?)
    }

    fn speed_joints(&mut self, qd: &[f64; 6], accel: f64) -> Result<i32, RobotError> {
        for x in qd {
            range("joint speed", *x, -MAX_JOINT_SPEED, MAX_JOINT_SPEED)?;
        }
        range("speed acceleration", accel, 1e-6, 40.0)?;
        self.check_motion_allowed()?;
        Ok(self.command(cmd::SPEEDJ, *qd, [accel, 0.0, 0.0])?)
    }

    fn stop(&mut self, decel: f64) -> Result<i32, RobotError> {
        range("stop deceleration", decel, 0.1, 40.0)?;
        Ok(self.command(cmd::STOPJ, [0.0; 6], [decel, 0.0, 0.0])?)
    }

    fn freedrive(&mut self) -> Result<i32, RobotError> {
        Ok(UrRobot::freedrive(self)?)
    }

    fn keep_alive(&mut self) -> Result<(), RobotError> {
        Ok(self.send()?)
    }
}

impl Drop for UrRobot {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.writer.shutdown(std::net::Shutdown::Both).ok();
        if let Some(t) = self.thread.take() {
            t.join().ok();
        }
    }
}

fn check_dashboard(config: &UrConfig, version: ControllerVersion) -> Result<(), UrError> {
    let mut d = Dashboard::connect(
        SocketAddr::new(config.host, config.dashboard_port),
        config.timeout,
    )?;
    if version.major == 5 && version.minor >= 6 && !d.is_in_remote_control()? {
        return Err(UrError::Refused {
            what: "network control: enable remote control on the teach pendant".into(),
        });
    }
    let safety = d.safety_mode()?;
    if !matches!(safety, SafetyMode::Normal | SafetyMode::Reduced) {
        return Err(UrError::Robot(RobotError::Fault(match safety {
            SafetyMode::ProtectiveStop => RobotFault::ProtectiveStop,
            SafetyMode::RobotEmergencyStop | SafetyMode::SystemEmergencyStop => {
                RobotFault::EmergencyStop
            }
            m => RobotFault::Safety(m),
        })));
    }
    let mode = d.robot_mode()?;
    if mode != RobotMode::Running {
        if !config.power_on {
            return Err(RobotError::Fault(RobotFault::NotRunning(mode)).into());
        }
        d.power_on()?;
        d.brake_release()?;
        let start = Instant::now();
        while d.robot_mode()? != RobotMode::Running {
            if start.elapsed() > config.program_start_timeout {
                return Err(UrError::Timeout {
                    what: "robot mode RUNNING after power on and brake release".into(),
                    ms: config.program_start_timeout.as_millis(),
                });
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
    Ok(())
}

fn state_thread(
    mut conn: RtdeConnection,
    recipe: Recipe,
    mut values: Vec<Value>,
    shared: Arc<Shared>,
    clock: Arc<dyn Clock>,
) {
    let mut last: Option<RobotState> = None;
    while !shared.stop.load(Ordering::Relaxed) {
        match conn.receive(&recipe, &mut values, true) {
            Ok(()) => match state_from_values(&values, clock.now_s()) {
                Some(s) => {
                    if let Some(why) = implausible(&s, last.as_ref()) {
                        // A corrupted stream: nothing in it can be trusted any more, this
                        // package or the framing of the next. The connection is dropped (the
                        // loop sees it lost and stops the arm); a re-arm connects afresh.
                        record(&shared, format!("an implausible state package: {why}"));
                        if let Some(mut s) = last {
                            s.connected = false;
                            shared.cell.publish(&encode_state(&s));
                        }
                        break;
                    }
                    shared.cell.publish(&encode_state(&s));
                    last = Some(s);
                    wake(&shared);
                }
                None => {
                    record(&shared, "a state package with a non-rigid TCP pose".into());
                }
            },
            Err(UrError::Timeout { .. }) => {
                // Silence: mark the connection down; keep listening in case it resumes.
                if let Some(mut s) = last {
                    s.connected = false;
                    shared.cell.publish(&encode_state(&s));
                    last = Some(s);
                }
            }
            Err(e) => {
                record(&shared, e.to_string());
                if let Some(mut s) = last {
                    s.connected = false;
                    shared.cell.publish(&encode_state(&s));
                }
                break;
            }
        }
    }
    conn.shutdown();
}

fn wake(shared: &Shared) {
    if let Ok(w) = shared.waiter.try_lock()
        && let Some(t) = w.as_ref()
    {
        t.unpark();
    }
}

fn record(shared: &Shared, e: String) {
    if let Ok(mut g) = shared.last_error.lock() {
        *g = Some(e);
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Isometry3;

    fn state(t: f64, q: f64) -> RobotState {
        RobotState {
            actual_qd: [0.1; 6],
            ..RobotState::at_rest(t, [q; 6], Isometry3::identity())
        }
    }

    #[test]
    fn a_state_that_follows_from_the_last_passes_and_corrupted_fields_are_named() {
        let a = state(10.0, 0.5);
        assert_eq!(implausible(&a, None), None);
        assert_eq!(implausible(&state(10.002, 0.5001), Some(&a)), None);
        // After a 2 s gap the arm may have moved far.
        assert_eq!(implausible(&state(12.0, 2.0), Some(&a)), None);
        let cases: [(RobotState, &str); 6] = [
            (
                RobotState {
                    actual_q: [f64::NAN; 6],
                    ..a
                },
                "actual_q",
            ),
            (
                RobotState {
                    actual_qd: [0.0, 0.0, 3.0e12, 0.0, 0.0, 0.0],
                    ..a
                },
                "actual_qd[2]",
            ),
            (
                RobotState {
                    tcp_force: [f64::INFINITY; 6],
                    ..a
                },
                "actual_TCP_force",
            ),
            (
                RobotState {
                    speed_scaling: -7.0,
                    ..a
                },
                "speed_scaling",
            ),
            (state(9.0, 0.5), "went back"),
            (state(10.002, 0.9), "actual_q[0] jumped"),
        ];
        for (s, field) in cases {
            let why = implausible(&s, Some(&a)).unwrap_or_else(|| panic!("{field} passed"));
            assert!(why.contains(field), "{why}");
        }
    }
}
