//! What a live session (`run`, `teach-goal`, `calibrate collect`) connects to, from the configuration: the
//! robot (a UR at an address, or an in-process simulated controller serving real RTDE on
//! loopback) and the tracker (an OpenIGTLink server, the simulated tracker serving the head
//! marker and the flange's calibration marker over OpenIGTLink on loopback, or the simulated
//! depth camera whose frames the paper's pipeline tracks, [`crate::camera`]).

use crate::camera::CameraServer;
use crate::camera_link::VisionLink;
use crate::config::{Setup, Timestamps, TrackerSource};
use crate::{AppError, Context};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, MonotonicClock};
use mocomp_igtl::client::{Client, ClientConfig, TimestampMode};
use mocomp_sim::contact::{Contact, ContactParams};
use mocomp_sim::{TrackedMarker, TrackerServer};
use mocomp_ur::{UrConfig, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimConfig, ToolLoad};
use std::io::Write;
use std::sync::{Arc, OnceLock};
use std::time::Instant;

/// The robot and tracker, connected. Dropping it stops the simulators.
pub struct World {
    /// The clock every part uses.
    pub clock: Arc<dyn Clock>,
    /// The robot client.
    pub robot: UrRobot,
    /// The tracker's address.
    pub tracker_addr: String,
    /// The real-time scheduling the calling thread got (when asked for).
    pub realtime: Option<mocomp_rt::RtReport>,
    /// Keeps the CPUs out of deep idle states while the world runs (held for its drop).
    _cpu_latency: Option<mocomp_rt::CpuLatencyGuard>,
    /// The simulated camera's pipeline parameters and newest frame (source "camera").
    pub vision: Option<Arc<VisionLink>>,
    // Dropped after the robot client (field order): the simulators.
    _stimulator: Option<Stimulator>,
    tracker: Option<Arc<TrackerServer>>,
    /// The depth camera (sources "camera" and "k4a").
    pub(crate) camera: Option<CameraServer>,
    pub(crate) sim: Option<Arc<Sim>>,
}

impl std::fmt::Debug for World {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("World")
            .field("tracker_addr", &self.tracker_addr)
            .field("simulated_robot", &self.sim.is_some())
            .finish_non_exhaustive()
    }
}

impl World {
    /// [`Self::connect`] at the loop's real-time settings (`[realtime]`), for a command that
    /// feeds the control program's 50 ms watchdog outside the loop (calibration, teaching): a
    /// normal thread that waits longer on a busy machine stops the arm mid-way. A refusal is a
    /// warning in `out`, not an error.
    pub fn connect_feeding_watchdog(
        setup: &Setup,
        initial_q: [f64; 6],
        out: &mut dyn Write,
    ) -> Result<Self, AppError> {
        let world = Self::connect(setup, initial_q, out, Some(&setup.file.realtime))?;
        if let Some(w) = world
            .realtime
            .as_ref()
            .and_then(mocomp_rt::RtReport::warning)
        {
            writeln!(out, "warning: {w}").what(|| "writing the notice")?;
        }
        Ok(world)
    }

    /// Starts what is simulated and connects the robot. `initial_q`: the simulated robot's joints
    /// at start.
    ///
    /// With `realtime`, the simulators are started from this thread at the simulators' FIFO
    /// priority and the robot client at the loop's, so their threads inherit those; this thread
    /// is left at the loop's priority (memory locked, pinned as configured) and the report says
    /// what the operating system granted. Clients started later from this thread (the tracker's)
    /// inherit the loop's priority too.
    pub fn connect(
        setup: &Setup,
        initial_q: [f64; 6],
        out: &mut dyn Write,
        realtime: Option<&mocomp_rt::RtConfig>,
    ) -> Result<Self, AppError> {
        let file = &setup.file;
        let realtime = realtime.filter(|c| c.enabled);
        if let Some(c) = realtime {
            // A refusal shows in the loop's report below (same cause); nothing to add here.
            if let Some(cpu) = c.simulator_cpu.or(c.cpu) {
                mocomp_rt::pin_to_cpu(cpu).ok();
            }
            mocomp_rt::set_fifo(c.simulator_priority).ok();
        }
        let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
        let host: std::net::IpAddr = file
            .robot
            .host
            .parse()
            .map_err(|e| AppError::Config(format!("robot.host {:?}: {e}", file.robot.host)))?;
        // The simulated head's time 0 (the simulated tracker's), once it has started.
        let head_t0: Arc<OnceLock<Instant>> = Arc::new(OnceLock::new());
        let (sim, ucfg) = start_robot(setup, initial_q, host, &head_t0, out)?;
        let tracker = if file.tracker.source == TrackerSource::Simulated {
            let t = start_tracker(setup, sim.clone())?;
            head_t0.set(t.started()).ok();
            Some(Arc::new(t))
        } else {
            None
        };
        let stimulator = match &sim {
            Some(sim) if file.session.simulated_stimulator.rate_hz > 0.0 => Some(
                Stimulator::start(setup, Arc::clone(sim), tracker.clone())
                    .what(|| "the simulated stimulator")?,
            ),
            _ => None,
        };
        let (camera, vision) = start_camera(setup)?;
        let tracker_addr = match (&tracker, &camera, &file.tracker.igtl) {
            // The simulated tracker seen through another address (a relay).
            (Some(_), _, Some(a)) => a.clone(),
            (Some(t), _, None) => t.addr().to_string(),
            (None, Some(c), _) => c.addr().to_string(),
            (None, None, Some(a)) => a.clone(),
            // The head's poses come over ROS 2 (`mocomp run` takes them from its node).
            (None, None, None) if file.tracker.source == TrackerSource::Ros2 => String::new(),
            (None, None, None) => {
                return Err(AppError::Config("tracker.igtl: needed".into()));
            }
        };
        if realtime.is_some_and(|c| c.cpu.is_none() && c.simulator_cpu.is_some()) {
            // The simulators are pinned; the loop is not.
            mocomp_rt::unpin().ok();
        }
        let (report, cpu_latency) = match realtime.map(|c| mocomp_rt::apply(c, c.priority)) {
            Some((r, g)) => (Some(r), g),
            None => (None, None),
        };
        let robot =
            UrRobot::connect(ucfg, Arc::clone(&clock)).what(|| format!("robot at {host}"))?;
        say(
            out,
            format!(
                "tracker {tracker_addr} ({}), device {}",
                file.tracker.source, file.tracker.device
            ),
        )?;
        Ok(Self {
            clock,
            robot,
            tracker_addr,
            realtime: report,
            _cpu_latency: cpu_latency,
            vision,
            _stimulator: stimulator,
            tracker,
            camera,
            sim,
        })
    }

    /// An OpenIGTLink client for `device`, with the configured timestamp handling (`auto`: a
    /// simulated tracker on this host is read as synchronized).
    pub fn client(&self, setup: &Setup, device: &str) -> Client {
        self.client_keeping(setup, device, 0)
    }

    /// [`Self::client`], keeping every message received in a channel of `keep_messages`.
    pub fn client_keeping(&self, setup: &Setup, device: &str, keep_messages: usize) -> Client {
        let t = &setup.file.tracker;
        let mut icfg = ClientConfig::new(&self.tracker_addr);
        icfg.keep_messages = keep_messages;
        icfg.device = Some(device.to_string());
        icfg.fixed_latency_s = t.fixed_latency_s;
        let simulated = self.tracker.is_some() || self.camera.is_some();
        icfg.timestamps = match t.timestamps {
            Timestamps::Synchronized => TimestampMode::Synchronized,
            Timestamps::Auto if simulated => TimestampMode::Synchronized,
            Timestamps::Auto | Timestamps::Estimated => TimestampMode::Estimated,
        };
        Client::start(icfg, Arc::clone(&self.clock))
    }

    /// Whether the robot is simulated.
    pub fn simulated_robot(&self) -> bool {
        self.sim.is_some()
    }
}

/// What the built-in simulated controller saw of the run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SimulatorFigures {
    /// Its own events, oldest first (the newest 256), each at its controller time (s): why it
    /// stopped the program or the arm, which the robot's state alone does not say.
    pub events: Vec<(f64, String)>,
    /// The largest servo setpoint speed it took, as a share of the speed it stops the arm for
    /// (C204A3): the loop's margin from a protective stop.
    pub setpoint_peak_share: f64,
    /// When that came, controller time (s).
    pub setpoint_peak_s: f64,
    /// Cycles its clock gave up (it was stopped for more than 25 ms, as a busy PC can stop a
    /// simulator and a real controller is never stopped): never run, so never answered, and not
    /// among the loop's missed cycles.
    pub cycles_given_up: u64,
}

/// [`SimulatorFigures`] of `sim` (`None`: a real robot, whose log is on its teach pendant).
pub(crate) fn simulator_figures(sim: Option<&Sim>) -> Option<SimulatorFigures> {
    sim.map(|sim| {
        let (events, (share, at)) = sim.with(|c| (c.events().0, c.setpoint_peak()));
        SimulatorFigures {
            events: events.into_iter().map(|e| (e.time_s, e.text)).collect(),
            setpoint_peak_share: share,
            setpoint_peak_s: at,
            cycles_given_up: sim.stats().cycles_given_up,
        }
    })
}

/// The simulated world's stimulator (`[session.simulated_stimulator]`): its trigger wired
/// through the gate output (`session.gate_output`; without one it is not gated), it fires at
/// `rate_hz` while the output is high, each pulse reported as the session takes it: 20 ms high
/// on the robot's `session.pulse_input` (longer than a CB3's 8 ms state period), or, without
/// one, a STRING `pulse` from device `Stimulator` on the simulated tracker's OpenIGTLink server.
struct Stimulator {
    stop: Arc<std::sync::atomic::AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Stimulator {
    fn start(
        setup: &Setup,
        sim: Arc<Sim>,
        tracker: Option<Arc<TrackerServer>>,
    ) -> std::io::Result<Self> {
        let s = &setup.file.session;
        let (gate, input, rate) = (s.gate_output, s.pulse_input, s.simulated_stimulator.rate_hz);
        // What a stimulator's bridge would say: `pulse`, with its output when configured.
        let text = match s.simulated_stimulator.output_pct {
            Some(v) => format!("pulse output={v}"),
            None => "pulse".to_string(),
        }
        .into_bytes();
        // One source of pulses: the robot's input when there is one, else the message.
        let by_message = (s.igtl_device.is_some() && input.is_none())
            .then_some(tracker)
            .flatten();
        let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
        let stopping = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("sim-stimulator".into())
            .spawn(move || {
                use std::sync::atomic::Ordering;
                let period = std::time::Duration::from_secs_f64(1.0 / rate);
                let width = std::time::Duration::from_millis(20);
                let mut next = Instant::now() + period;
                while !stopping.load(Ordering::Relaxed) {
                    let now = Instant::now();
                    if now < next {
                        std::thread::sleep((next - now).min(std::time::Duration::from_millis(20)));
                        continue;
                    }
                    next += period;
                    let open = gate
                        .is_none_or(|b| sim.with(|c| c.io().digital_outputs()) & (1u64 << b) != 0);
                    if !open {
                        continue;
                    }
                    if let Some(t) = &by_message
                        && let Ok(mut m) = mocomp_igtl::Message::new(
                            "STRING",
                            "Stimulator",
                            mocomp_igtl::message::Body::String {
                                encoding: 3,
                                text: text.clone(),
                            },
                        )
                    {
                        // Stamped with its own clock (this machine's), as the record keeps it.
                        m.timestamp = mocomp_igtl::Timestamp::now();
                        t.send(&m);
                    }
                    if let Some(b) = input {
                        sim.with(|c| c.set_digital_input(b, true));
                        std::thread::sleep(width);
                        sim.with(|c| c.set_digital_input(b, false));
                    }
                }
            })?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }
}

impl Drop for Stimulator {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join().ok();
        }
    }
}

/// The simulated robot's tool meets the simulated head's scalp ([`mocomp_sim::contact`], the
/// configured head and coil models, a sensor with [`mocomp_sim::contact::SIMULATED_SENSOR_NOISE_N`] of
/// noise): the head where the simulated tracker's truth puts it, at the same instant.
fn scalp_contact(setup: &Setup, head_t0: Arc<OnceLock<Instant>>) -> Result<ToolLoad, AppError> {
    let file = &setup.file;
    let s = &file.tracker.simulated;
    let rest = s.base_from_head.iso();
    let trajectory = s.motion.trajectory();
    let tcp_from_coil = file.flange_from_coil()?;
    let mut law = Contact::new(
        ContactParams {
            noise_n: mocomp_sim::contact::SIMULATED_SENSOR_NOISE_N,
            ..ContactParams::default()
        },
        file.head_model()?,
        file.coil_model(),
        s.model.seed,
    );
    Ok(ToolLoad::new(move |t, base_from_tcp| {
        let Some(t0) = head_t0.get() else {
            // No head yet: free space, the sensor's noise only.
            let far = Isometry3::translation(100.0, 0.0, 0.0);
            return law.wrench(t, &far, &Isometry3::identity());
        };
        let base_from_head = rest * trajectory.rest_from_head(t0.elapsed().as_secs_f64());
        law.wrench(t, &(base_from_tcp * tcp_from_coil), &base_from_head)
    }))
}

/// Where the simulated tracker truly is in the robot's base: `[tracker.simulated]
/// base_from_tracker`, else the calibration's.
fn tracker_from_base(setup: &Setup) -> Isometry3<f64> {
    match &setup.file.tracker.simulated.base_from_tracker {
        Some(y) => y.iso(),
        None => setup.base_from_tracker,
    }
    .inverse()
}

/// The simulated head marker in the tracker's view `t` seconds into its motion
/// (`[tracker.simulated]`: at rest where `base_from_head` says, moving as `motion` says).
pub fn simulated_head(setup: &Setup) -> impl Fn(f64) -> Isometry3<f64> + Clone + Send + 'static {
    let s = &setup.file.tracker.simulated;
    let tracker_from_base = tracker_from_base(setup);
    let rest = s.base_from_head.iso();
    let trajectory = s.motion.trajectory();
    move |t| tracker_from_base * rest * trajectory.rest_from_head(t)
}

/// How many loopback addresses past a taken `robot.host` the simulated robot tries.
const FREE_LOOPBACK_TRIES: u8 = 32;

/// One line of progress to `out`.
fn say(out: &mut dyn Write, line: String) -> Result<(), AppError> {
    writeln!(out, "{line}").what(|| "writing the progress")
}

/// The robot: a simulated controller started on `host` (another loopback address when its ports
/// are taken), or the real one at `host`.
fn start_robot(
    setup: &Setup,
    initial_q: [f64; 6],
    host: std::net::IpAddr,
    head_t0: &Arc<OnceLock<Instant>>,
    out: &mut dyn Write,
) -> Result<(Option<Arc<Sim>>, UrConfig), AppError> {
    let file = &setup.file;
    if !file.robot.simulate {
        return Ok((None, UrConfig::new(host)));
    }
    let mut ctrl = ControllerConfig::new(setup.model);
    ctrl.initial_q = initial_q;
    if file.tracker.source == TrackerSource::Simulated {
        ctrl.tool_load = Some(scalp_contact(setup, Arc::clone(head_t0))?);
    }
    let (sim, on) = start_sim_free(&ctrl, host)?;
    let u = sim.ur_config();
    say(
        out,
        if on == host {
            format!("simulated {} on {host}", file.robot.model)
        } else {
            format!(
                "simulated {} on {on} (robot.host {host}: its ports are taken)",
                file.robot.model
            )
        },
    )?;
    Ok((Some(Arc::new(sim)), u))
}

/// The depth camera and its vision link, for the sources "camera" and "k4a".
fn start_camera(
    setup: &Setup,
) -> Result<(Option<CameraServer>, Option<Arc<VisionLink>>), AppError> {
    let file = &setup.file;
    Ok(match file.tracker.source {
        TrackerSource::Camera => {
            let link = VisionLink::new(file.tracker.camera.params);
            (
                Some(crate::camera::sim::start(setup, Arc::clone(&link))?),
                Some(link),
            )
        }
        TrackerSource::K4a => {
            let link = VisionLink::new(file.tracker.k4a.params);
            (
                Some(crate::camera::k4a::start(setup, Arc::clone(&link))?),
                Some(link),
            )
        }
        _ => (None, None),
    })
}

/// Starts the simulated robot on `host`, or, where a UR port there is taken and `host` is a
/// loopback address, on the next loopback address whose ports are free (the simulated world's
/// robot is reached only through this process, so any will do). Elsewhere, or when none is
/// free, the error names `robot.host`.
fn start_sim_free(
    ctrl: &ControllerConfig,
    host: std::net::IpAddr,
) -> Result<(Sim, std::net::IpAddr), AppError> {
    let mut on = host;
    for _ in 0..=FREE_LOOPBACK_TRIES {
        match Sim::start(SimConfig::new(ctrl.clone(), on)) {
            Ok(sim) => return Ok((sim, on)),
            Err(mocomp_ursim::SimError::Bind { source, .. })
                if source.kind() == std::io::ErrorKind::AddrInUse
                    && let Some(next) = next_loopback(on) =>
            {
                on = next;
            }
            Err(e) => {
                return Err(e).what(|| {
                    format!(
                        "robot.host {host}: the simulated robot (set robot.host to a free \
                         loopback address: 127.0.0.2, 127.0.0.3, …)"
                    )
                });
            }
        }
    }
    Err(AppError::Config(format!(
        "robot.host {host}: the UR ports of it and the next {FREE_LOOPBACK_TRIES} loopback \
         addresses are taken"
    )))
}

/// The loopback address after `a` (`None`: not loopback, or the last).
fn next_loopback(a: std::net::IpAddr) -> Option<std::net::IpAddr> {
    match a {
        std::net::IpAddr::V4(v4) if v4.is_loopback() => {
            let o = v4.octets();
            (o[3] < 254).then(|| std::net::Ipv4Addr::new(o[0], o[1], o[2], o[3] + 1).into())
        }
        _ => None,
    }
}

/// The simulated tracker: the head marker (moving as configured) and, when the robot is
/// simulated, the calibration marker on its flange (at the simulated robot's joints).
fn start_tracker(setup: &Setup, sim: Option<Arc<Sim>>) -> Result<TrackerServer, AppError> {
    let file = &setup.file;
    let s = &file.tracker.simulated;
    let head = simulated_head(setup);
    let tracker_from_base = tracker_from_base(setup);
    let mut markers = vec![TrackedMarker {
        device: file.tracker.device.clone(),
        truth: Box::new(move |t| Some(head(t))),
    }];
    if let Some(sim) = sim {
        let flange_from_marker = s.flange_from_marker.iso();
        let arm = setup.arm;
        markers.push(TrackedMarker {
            device: file.calibrate.device.clone(),
            truth: Box::new(move |_| {
                let q = sim.with(|c| c.q());
                Some(tracker_from_base * arm.fk_flange(&q) * flange_from_marker)
            }),
        });
    }
    TrackerServer::start(&s.serve, s.model, markers)
        .what(|| format!("tracker.simulated.serve {}: the simulated tracker", s.serve))
}

/// Starts a simulated controller of `model` on the standard ports of `host` (for `mocomp ursim`
/// and `robot --ursim`), at the options' joints. It stands for the controller's own computer, so
/// its threads run at the options' `SCHED_FIFO` priority (and CPU) where the operating system
/// allows: they inherit them from the calling thread, which is left so. Returns it with a
/// warning naming what was refused; joints outside the limits are a configuration error.
pub fn start_simulator(
    model: mocomp_kin::Model,
    host: std::net::IpAddr,
    options: &SimulatorOptions,
) -> Result<(Sim, Option<String>), AppError> {
    let mut warnings = Vec::new();
    if let Some(cpu) = options.cpu
        && let Err(e) = mocomp_rt::pin_to_cpu(cpu)
    {
        warnings.push(format!("not pinned to CPU {cpu}: {e}"));
    }
    if let Some(priority) = options.priority
        && let Err(e) = mocomp_rt::set_fifo(priority)
    {
        warnings.push(format!(
            "no real-time scheduling (SCHED_FIFO {priority}): {e}"
        ));
    }
    let mut controller = ControllerConfig::new(model);
    if let Some(q) = options.initial_q {
        let arm = mocomp_kin::Arm::new(model);
        if !arm.limits().contains(&q, 0.0) {
            return Err(AppError::Config(format!(
                "initial joints {q:?}: outside the {model}'s joint limits"
            )));
        }
        controller.initial_q = q;
    }
    let sim = Sim::start(SimConfig::new(controller, host)).what(|| {
        format!(
            "starting the simulated {model} on {host} (each simulator needs its own loopback \
             address: 127.0.0.2, 127.0.0.3, …)"
        )
    })?;
    let warning = (!warnings.is_empty())
        .then(|| format!("the simulated controller runs with {}", warnings.join("; ")));
    Ok((sim, warning))
}

/// How a stand-alone simulated controller starts: as a real one would, at its own pose and
/// priority.
#[derive(Debug, Clone, PartialEq)]
pub struct SimulatorOptions {
    /// The arm's joints at power-on (default: the simulator's working pose).
    pub initial_q: Option<[f64; 6]>,
    /// `SCHED_FIFO` priority of its threads (`None`: normal scheduling).
    pub priority: Option<u8>,
    /// Pin its threads to this CPU.
    pub cpu: Option<usize>,
}

impl Default for SimulatorOptions {
    /// The working pose, at the configured simulators' FIFO priority, unpinned.
    fn default() -> Self {
        Self {
            initial_q: None,
            priority: Some(mocomp_rt::RtConfig::default().simulator_priority),
            cpu: None,
        }
    }
}

/// Prints the simulator's addresses, then its events as they happen, until `seconds` have passed
/// (then its counters) or forever (`mocomp ursim`).
pub fn serve_simulator(
    out: &mut dyn Write,
    sim: &Sim,
    model: mocomp_kin::Model,
    seconds: Option<f64>,
) -> std::io::Result<()> {
    use std::time::{Duration, Instant};
    let a = sim.addrs();
    let v = sim.with(|c| c.config().version());
    writeln!(
        out,
        "simulated {model} (controller {v}, {:.0} Hz): RTDE {}, dashboard {}, script {} / {} / {}",
        1.0 / sim.with(|c| c.period_s()),
        a.rtde,
        a.dashboard,
        a.primary,
        a.secondary,
        a.realtime
    )?;
    out.flush()?;
    let start = Instant::now();
    let mut seen = 0;
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let (events, total) = sim.with(|c| c.events());
        let new = (total - seen) as usize;
        for e in events.iter().skip(events.len().saturating_sub(new)) {
            writeln!(out, "[{:10.3} s] {}", e.time_s, e.text)?;
        }
        seen = total;
        out.flush()?;
        if seconds.is_some_and(|s| start.elapsed().as_secs_f64() >= s) {
            let st = sim.stats();
            let (peak, at) = sim.with(|c| c.setpoint_peak());
            writeln!(
                out,
                "{} cycles, {} inputs, {} outputs ({} skipped), {} bad packages, {} overruns, \
                 {} watchdog cycles deferred (input waiting unread); fastest servo setpoint \
                 {:.0} % of a jump's speed (at {at:.3} s)",
                st.ticks,
                st.inputs,
                st.outputs,
                st.outputs_skipped,
                st.bad_packages,
                st.overruns,
                st.watchdog_deferred,
                100.0 * peak
            )?;
            return Ok(());
        }
    }
}
