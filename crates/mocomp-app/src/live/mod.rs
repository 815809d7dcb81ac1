//! The live session (`mocomp run`): the compensation loop in real time, until stopped or
//! `duration_s`.
//!
//! The robot is a UR controller at an address, or an in-process simulated controller
//! (`mocomp-ursim`, real time, real RTDE over loopback). The tracker is an OpenIGTLink server
//! (PLUS, Slicer, a tracker), or an in-process simulated tracker that serves the moving head over
//! OpenIGTLink on loopback, so the loop always reads poses through the real client. The loop runs
//! on this thread at the robot's rate; each cycle's record goes through a bounded lock-free
//! channel to a logger thread that writes the CSV, tells an [`Observer`] of each cycle, each event
//! and, once a second, of the loop's status, and keeps the figures of the [`RunReport`]. A front
//! end steers the loop through its [`Controls`] (lock-free: flags and a one-slot channel the loop
//! polls): the stop (Ctrl-C, the console's stop) ends the loop, and the robot is then stopped
//! (stopj) and the report says how that went; the operator's hold and resume; new loop
//! parameters.

pub mod logger;
pub mod ros2;
pub mod session;
pub mod session_link;
pub mod session_wiring;
pub mod slicer;
pub mod tuning;

use crate::config::Setup;
use crate::frontend::{Controls, Note, Observer, RearmOutcome, Selection};
pub use crate::live::logger::{RecordOutcome, Ros2Figures, RunReport, StopOutcome, TrackerFigures};
use crate::live::logger::{Summary, logger};
use crate::live::session::{LoopSession, SessionReport};
use crate::live::session_link::{SessionLogSide, SessionStart};
use crate::world::World;
use crate::{AppError, Context};
use mocomp_control::drive::Requests;
use mocomp_control::{Compensator, CycleRecord, LoopParams, Mode};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, PoseSource};
use mocomp_ur::recovery::RecoveryError;
use mocomp_ur::{Robot, UrRobot};
use std::io::Write;
use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, TrySendError, sync_channel};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// How long the run waits for standstill after its stop.
const STANDSTILL_WAIT: Duration = Duration::from_secs(3);

/// The live pace: a cycle per new robot state, on the monotonic clock, until stopped.
struct Live<'a> {
    robot: UrRobot,
    /// The head's poses: OpenIGTLink, or the ROS 2 node's topic.
    source: Box<dyn PoseSource>,
    clock: &'a dyn Clock,
    controls: &'a Controls,
    /// The loop's end of the parameter channel (`None`: another loop took it).
    params: Option<Receiver<LoopParams>>,
    /// The loop's end of the goal channel.
    goals: Option<Receiver<Isometry3<f64>>>,
    /// The loop's end of the target channel.
    targets: Option<Receiver<Selection>>,
    /// The session beside the loop.
    session: LoopSession,
    /// The start target's goal, for the first cycle.
    start_goal: Option<Isometry3<f64>>,
    /// The operator's hold as last passed on.
    held: bool,
    /// Free-drive as last passed on.
    guided: bool,
    t_end: f64,
    /// The robot state count of the last cycle.
    seen: u64,
    /// Without a new state this long, cycle anyway: the loop resends its command (the watchdog
    /// stays fed) and its stale-state rule stops the robot once the state is really stale.
    patience: Duration,
    tx: &'a SyncSender<CycleRecord>,
    /// Records the logger could not take.
    dropped: u64,
    /// The operator's resumes already acted on.
    resumes_seen: u64,
    /// The last cycle ended faulted.
    faulted: bool,
    /// The robot's recovery is done: the controller is re-armed before the next cycle.
    rearm: bool,
    /// A state older than this (s) means the state stream is dead (a re-arm reconnects).
    stream_dead_s: f64,
}

impl Live<'_> {
    /// Waits (up to a second) for a fresh first state: the first cycle must not judge a state
    /// received while the rest of the world was still starting. The program's watchdog is fed
    /// meanwhile; it does not wait for the first cycle.
    fn start(&mut self, period: f64) {
        let ready_by = Instant::now() + Duration::from_secs(1);
        while Instant::now() < ready_by
            && !self
                .robot
                .state()
                .is_some_and(|s| self.clock.now_s() - s.received_s < period)
        {
            self.robot.keep_alive().ok();
            self.seen = self.robot.wait_for_state(self.seen, self.patience);
        }
    }
}

impl Live<'_> {
    /// The operator resumed a faulted loop: the robot's own recovery, between cycles (the arm is
    /// stopped, and a reconnect or a program upload takes longer than a cycle), then the
    /// controller is re-armed at the next one. What it did, or why not, is the session's note.
    fn recover(&mut self) {
        let now = self.clock.now_s();
        let outcome = match self.robot.recover(now, self.stream_dead_s) {
            Ok(done) => {
                self.rearm = true;
                RearmOutcome::Done(done)
            }
            Err(RecoveryError::Refused(r)) => RearmOutcome::Refused(r),
            Err(RecoveryError::Failed { step, .. }) => RearmOutcome::Failed(step),
        };
        // A new connection counts its states afresh.
        self.seen = self.robot.state_count();
        self.session.note(Note::Rearm(self.clock.now_s(), outcome));
    }
}

impl mocomp_control::drive::Pace for Live<'_> {
    type Error = std::convert::Infallible;

    fn next_cycle(&mut self) -> Result<Option<f64>, Self::Error> {
        if self.controls.stop_requested() || self.clock.now_s() >= self.t_end {
            return Ok(None);
        }
        let resumes = self.controls.resumes();
        if resumes != self.resumes_seen {
            self.resumes_seen = resumes;
            if self.faulted {
                self.recover();
            }
        }
        self.seen = self.robot.wait_for_state(self.seen, self.patience);
        Ok(Some(self.clock.now_s()))
    }

    fn loop_io(&mut self) -> (&mut dyn Robot, &mut dyn PoseSource) {
        (&mut self.robot, self.source.as_mut())
    }

    fn cycle_done(&mut self, mut record: CycleRecord) -> Result<(), Self::Error> {
        self.faulted = matches!(record.mode, Mode::Faulted(_));
        self.session.after_cycle(&mut record, &mut self.robot);
        if let Err(TrySendError::Full(_)) = self.tx.try_send(record) {
            self.dropped += 1;
        }
        Ok(())
    }

    fn requests(&mut self) -> Requests {
        let hold = self.controls.hold();
        let changed = (hold != self.held).then_some(hold);
        self.held = hold;
        let guided = self.controls.freedrive();
        let freedrive = (guided != self.guided).then_some(guided);
        self.guided = guided;
        let params = match self.params.as_ref().map(Receiver::try_recv) {
            Some(Ok(p)) => Some(p),
            Some(Err(TryRecvError::Empty | TryRecvError::Disconnected)) | None => None,
        };
        let mut goal = match self.goals.as_ref().map(Receiver::try_recv) {
            Some(Ok(g)) => Some(g),
            Some(Err(TryRecvError::Empty | TryRecvError::Disconnected)) | None => None,
        };
        if let Some(Ok((index, g))) = self.targets.as_ref().map(Receiver::try_recv) {
            self.session.select(self.clock.now_s(), index);
            goal = Some(g);
        }
        if let Some(g) = self.start_goal.take() {
            goal = Some(g);
        }
        Requests {
            hold: changed,
            params,
            goal,
            calibration_invalid: self.session.calibration_invalid(),
            freedrive,
            rearm: std::mem::take(&mut self.rearm),
        }
    }
}

/// Where the head's poses come from when not from the tracker's OpenIGTLink client (a front
/// end's, such as ROS 2's topic): made on the loop's clock once the world is up.
pub type HeadSource = Box<dyn FnOnce(Arc<dyn Clock>) -> Box<dyn PoseSource> + Send>;

/// What to say before the loop starts, each line with its kind (`warning: `, `note: `): a head
/// model that is not the patient's, the session's wiring, the registration accepted (with `why`
/// when its gate would otherwise refuse it; a refusal is the error), a simulated tracker's
/// predictor.
pub fn start_notes(
    setup: &Setup,
    accept_registration: Option<&str>,
) -> Result<Vec<String>, AppError> {
    let file = &setup.file;
    let mut notes: Vec<String> = file
        .head_note()
        .map(|w| format!("warning: {w}"))
        .into_iter()
        .collect();
    notes.extend(
        session_wiring::notes(file)
            .into_iter()
            .map(|n| format!("warning: {n}")),
    );
    if let Some(n) = crate::registration::gate::registration_gate(setup, accept_registration)? {
        notes.push(format!("note: {n}"));
    }
    if file.tracker.source == crate::config::TrackerSource::Simulated
        && let Some(n) = file.predictor_note()
    {
        notes.push(format!("note: {n}"));
    }
    Ok(notes)
}

/// Runs the loop on `setup` until `controls` asks it to stop or `duration_s`, then stops the
/// robot and returns the report. `log_csv`: every cycle's record. `progress` is told what
/// starts; the `observer`, what happens while the loop runs; `head`: the head's poses when
/// `tracker.source` is not served over OpenIGTLink. The front ends are attached by the caller,
/// through `controls` and `observer`.
pub fn run(
    setup: &Setup,
    log_csv: Option<&Path>,
    controls: &Controls,
    observer: Box<dyn Observer>,
    head: Option<HeadSource>,
    progress: &mut dyn Write,
) -> Result<RunReport, AppError> {
    if head.is_none() && setup.file.tracker.source == crate::config::TrackerSource::Ros2 {
        refuse!("tracker.source = \"ros2\" without the ROS 2 node's head poses");
    }
    let period = setup.model.spec().series.period_s();
    let cfg = setup.loop_config()?;
    let q0 = setup.initial_joints()?;
    // What the loop needs besides the world is made before the robot is connected: once
    // connected, its control program stops when no command comes for 50 ms (the watchdog), and
    // a thread started on a busy machine can take longer than that. The logger:
    let csv = match log_csv {
        Some(p) => Some(std::fs::File::create(p).what(|| format!("log_csv {}", p.display()))?),
        None => None,
    };
    let (tx, rx) = sync_channel::<CycleRecord>(8192);
    let (session, session_log) = SessionStart::open(setup)?;
    let loop_clock: Arc<OnceLock<Arc<dyn Clock>>> = Arc::new(OnceLock::new());
    let log_thread = start_logger(rx, period, csv, &loop_clock, observer, session_log)?;

    let stream_dead_s = cfg.params.robot_rearm_after_s;
    let mut comp = Compensator::new(cfg, setup.arm, period);
    let file = &setup.file;
    let world = World::connect(setup, q0, progress, Some(&file.realtime))?;
    let realtime = world.realtime.clone();
    if let Some(w) = realtime.as_ref().and_then(mocomp_rt::RtReport::warning) {
        writeln!(progress, "warning: {w}").what(|| "writing the progress")?;
    }
    let clock = Arc::clone(&world.clock);
    // Set once, here: it cannot have been set before.
    loop_clock.set(Arc::clone(&clock)).ok();
    if let Some(v) = &world.vision {
        controls.attach_vision(Arc::clone(v));
    }
    let client = head
        .is_none()
        .then(|| world.client(setup, &file.tracker.device));
    let (loop_session, session) = session.connect(setup, &world, &clock, controls)?;
    // The simulators (the rest of `world`) stay up until the end of this function.
    let mut robot = world.robot;
    if file.robot.zero_force_sensor {
        robot
            .zero_force_sensor()
            .what(|| "robot.zero_force_sensor")?;
        writeln!(progress, "force/torque sensor zeroed").what(|| "writing the progress")?;
    }
    let source = head_source(client.as_ref(), head, &clock)?;
    progress.flush().what(|| "writing the progress")?;

    // The loop, at the robot's rate: one cycle per new state.
    let t_end = if file.duration_s > 0.0 {
        clock.now_s() + file.duration_s
    } else {
        f64::INFINITY
    };
    let mut pace = Live {
        seen: robot.state_count(),
        robot,
        source,
        clock: clock.as_ref(),
        controls,
        params: controls.take_params(),
        goals: controls.take_goals(),
        targets: controls.take_targets(),
        session: loop_session,
        start_goal: session.start_goal,
        held: false,
        guided: false,
        t_end,
        patience: Duration::from_secs_f64(3.0 * period),
        tx: &tx,
        dropped: 0,
        resumes_seen: controls.resumes(),
        faulted: false,
        rearm: false,
        stream_dead_s,
    };
    pace.start(period);
    // The live pace never fails: a late or missing state is the supervisor's to judge.
    match mocomp_control::drive(&mut comp, &mut pace, &mocomp_geom::MonotonicClock::new()) {
        Ok(()) => {}
        Err(never) => match never {},
    }
    let Live {
        mut robot,
        dropped,
        session: mut loop_session,
        ..
    } = pace;
    loop_session.close(&mut robot);
    let stop = stop_robot(robot, comp.config().params.stop_decel_rad_s2);
    let final_mode = comp.mode();
    let session_client = session.finish();
    drop(tx);
    drop(loop_session);
    let (mut s, session_report) = log_thread
        .join()
        .map_err(|_| AppError::Refused("the logger thread panicked".into()))?;
    s.dropped = dropped;
    let tracker = client.as_ref().map(|c| TrackerFigures::from(c.counters()));
    drop(client);
    drop(session_client);
    let mut report = RunReport::new(&mut s, realtime.as_ref(), &final_mode, stop, session_report);
    report.tracker = tracker;
    report.camera = world
        .camera
        .as_ref()
        .map(crate::camera::CameraServer::report);
    report.simulator = crate::world::simulator_figures(world.sim.as_deref());
    Ok(report)
}

/// The head's poses: the tracker over OpenIGTLink, or the front end's `head` (ROS 2's topic).
fn head_source(
    client: Option<&mocomp_igtl::client::Client>,
    head: Option<HeadSource>,
    clock: &Arc<dyn Clock>,
) -> Result<Box<dyn PoseSource>, AppError> {
    Ok(match (client, head) {
        (Some(c), _) => Box::new(c.pose_source()),
        (None, Some(head)) => head(Arc::clone(clock)),
        (None, None) => refuse!("no source of the head's poses"),
    })
}

/// The logger's thread: the CSV, the `observer`, the session's notes and log, the figures.
fn start_logger(
    rx: Receiver<CycleRecord>,
    period: f64,
    csv: Option<std::fs::File>,
    loop_clock: &Arc<OnceLock<Arc<dyn Clock>>>,
    observer: Box<dyn Observer>,
    session_log: SessionLogSide,
) -> Result<std::thread::JoinHandle<(Summary, SessionReport)>, AppError> {
    let clock = Arc::clone(loop_clock);
    let mut side = session_log;
    std::thread::Builder::new()
        .name("mocomp-log".into())
        .spawn(move || {
            // Whatever the thread that starts it runs at, the logger must not compete with the
            // real-time loop, nor sit on its core.
            mocomp_rt::leave_realtime().ok();
            let mut observer = observer;
            let s = logger(rx, period, csv, &clock, observer.as_mut(), &mut side);
            side.log.finish();
            (s, side.log.report)
        })
        .what(|| "starting the logger thread")
}

/// Stops the robot in a defined way, waits for standstill, and closes the connection at once:
/// the logger's and the session's ends may take longer than the program's watchdog.
fn stop_robot(mut robot: UrRobot, decel: f64) -> StopOutcome {
    let sent = robot.stop(decel);
    let t_stop = Instant::now();
    let still = loop {
        let still = robot
            .state()
            .is_some_and(|s| s.actual_qd.iter().all(|v| v.abs() < 1e-3));
        if still || t_stop.elapsed() >= STANDSTILL_WAIT {
            break still;
        }
        // The program's watchdog judges silence, not motion: fed while the arm brakes, so the
        // program ends by the EXIT below, not by the watchdog.
        robot.keep_alive().ok();
        std::thread::sleep(Duration::from_millis(5));
    };
    // The robot stands still (or the report says it does not): a failed close changes nothing.
    robot.close().ok();
    let after_s = t_stop.elapsed().as_secs_f64();
    match (sent, still) {
        (Ok(_), true) => StopOutcome::Standstill { after_s },
        (Err(e), true) => StopOutcome::AlreadyStopped { why: e.to_string() },
        (sent, false) => StopOutcome::StillMoving {
            after_s,
            refused: sent.err().map(|e| e.to_string()),
        },
    }
}
