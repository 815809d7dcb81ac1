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

use crate::config::Setup;
use crate::driver::Requests;
use crate::frontend::{
    Both, Controls, Note, Observer, RearmOutcome, Selection, Status, mode_name, note_time,
};
use crate::live_session::{LoopSession, SessionLog, SessionReport, SessionSetup};
use crate::world::World;
use crate::{AppError, Context};
use mocomp_control::{Compensator, CycleRecord, Event, LoopParams, Mode, Reason};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, PoseSource};
use mocomp_ur::recovery::RecoveryError;
use mocomp_ur::{Robot, UrRobot};
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TryRecvError, TrySendError, sync_channel};
use std::sync::{Arc, OnceLock, PoisonError};
use std::time::{Duration, Instant};

/// What the logger keeps for the summary.
#[derive(Debug, Default)]
struct Summary {
    cycles: u64,
    /// Records the loop could not queue (the logger fell behind).
    dropped: u64,
    first_t: Option<f64>,
    last_t: f64,
    missed: u64,
    period_ms: Vec<f64>,
    compute_us: Vec<f64>,
    delay_ms: Vec<f64>,
    deviation_mm: Vec<f64>,
    deviation_deg: Vec<f64>,
    /// The contact force read each cycle (with `force_sensing`), N.
    contact_force_n: Vec<f64>,
    by_mode: [u64; 5],
    events: Vec<(f64, Event)>,
    /// The session's notes, in words.
    session_lines: Vec<(f64, String)>,
    /// Why the CSV log stopped being written, if it did.
    log_error: Option<String>,
}

/// The controller's protective stops among `events`: a protective stop latches until the
/// operator's re-arm, so its hold entered again before one (after a stale state in between, say)
/// is the same stop.
fn protective_stops(events: &[(f64, Event)]) -> usize {
    let mut in_stop = false;
    let mut n = 0;
    for (_, e) in events {
        match e {
            Event::Hold(Reason::Robot(mocomp_ur::RobotFault::ProtectiveStop)) if !in_stop => {
                in_stop = true;
                n += 1;
            }
            Event::Rearmed => in_stop = false,
            _ => {}
        }
    }
    n
}

/// How long the run waits for standstill after its stop.
const STANDSTILL_WAIT: Duration = Duration::from_secs(3);

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// The session's notes and log, on the logger's thread.
struct SessionSide {
    notes: Receiver<Note>,
    log: SessionLog,
}

impl SessionSide {
    fn drain(&mut self, s: &mut Summary, observer: &mut dyn Observer) {
        while let Ok(n) = self.notes.try_recv() {
            let t = note_time(&n);
            let line = self.log.take(&n);
            observer.session(t, &line);
            s.session_lines.push((t, line));
        }
    }
}

fn logger(
    rx: Receiver<CycleRecord>,
    period: f64,
    csv: Option<std::fs::File>,
    clock: &OnceLock<Arc<dyn Clock>>,
    observer: &mut dyn Observer,
    session: &mut SessionSide,
) -> Summary {
    let mut s = Summary::default();
    let mut w = csv.map(csv::Writer::from_writer);
    // A log that cannot be written (a full disk) is not dropped silently: it stops logging, and
    // the run reports it and fails once the robot is stopped.
    let mut log_error: Option<csv::Error> = None;
    if let Some(w) = w.as_mut() {
        let header = [
            "t_s",
            "mode",
            "event",
            "sample_age_ms",
            "horizon_ms",
            "command_delay_ms",
            "head_speed_mm_s",
            "head_speed_deg_s",
            "deviation_mm",
            "deviation_deg",
            "path_m",
            "compute_us",
            "q1_cmd",
            "q2_cmd",
            "q3_cmd",
            "q4_cmd",
            "q5_cmd",
            "q6_cmd",
            "q1",
            "q2",
            "q3",
            "q4",
            "q5",
            "q6",
            "contact_force_n",
            "contact_axial_n",
            "press_mm",
        ];
        if let Err(e) = w.write_record(header) {
            log_error = Some(e);
        }
    }
    let mut last_status = Instant::now();
    // Since the last status line: cycles and the largest deviation while tracking (mm).
    let (mut window_cycles, mut window_max) = (0u64, 0.0f64);
    for r in rx {
        observer.cycle(&r, clock.get().map_or(f64::NAN, |c| c.now_s() - r.t));
        s.cycles += 1;
        window_cycles += 1;
        if s.first_t.is_none() {
            s.first_t = Some(r.t);
        } else {
            s.period_ms.push((r.t - s.last_t) * 1e3);
            if r.t - s.last_t > 1.5 * period {
                s.missed += ((r.t - s.last_t) / period).round() as u64 - 1;
            }
        }
        s.last_t = r.t;
        s.by_mode[r.mode.kind()] += 1;
        s.compute_us.push(r.compute_ns as f64 / 1e3);
        s.delay_ms.push(r.command_delay_s * 1e3);
        // The measured flange against the goal for the head estimated at the same time (not the
        // goal the command aims at, which is the head predicted a horizon ahead).
        let (dev_mm, dev_deg) = (r.deviation.0 * 1e3, r.deviation.1.to_degrees());
        if r.mode == Mode::Tracking && dev_mm.is_finite() {
            s.deviation_mm.push(dev_mm);
            s.deviation_deg.push(dev_deg);
            window_max = window_max.max(dev_mm);
        }
        if r.contact_force_n.is_finite() {
            s.contact_force_n.push(r.contact_force_n);
        }
        if let Some(e) = r.event {
            s.events.push((r.t, e));
            observer.event(r.t, &e);
        }
        session.drain(&mut s, observer);
        if let Some(w) = w.as_mut().filter(|_| log_error.is_none()) {
            let (path, _) = r.path.unwrap_or((f64::NAN, f64::NAN));
            let mut row = vec![
                format!("{:.6}", r.t),
                mode_name(&r.mode),
                r.event.map(|e| format!("{e:?}")).unwrap_or_default(),
                format!("{:.3}", r.sample_age_s * 1e3),
                format!("{:.3}", r.horizon_s * 1e3),
                format!("{:.3}", r.command_delay_s * 1e3),
                format!("{:.2}", r.head_speed.0 * 1e3),
                format!("{:.2}", r.head_speed.1.to_degrees()),
                format!("{dev_mm:.4}"),
                format!("{dev_deg:.4}"),
                format!("{path:.4}"),
                format!("{:.2}", r.compute_ns as f64 / 1e3),
            ];
            row.extend(
                r.q_command
                    .iter()
                    .chain(r.q_actual.iter())
                    .map(|q| format!("{q:.6}")),
            );
            row.extend([
                format!("{:.3}", r.contact_force_n),
                format!("{:.3}", r.contact_axial_n),
                format!("{:.4}", r.press_m * 1e3),
            ]);
            if let Err(e) = w.write_record(&row) {
                log_error = Some(e);
            }
        }
        if last_status.elapsed() >= Duration::from_secs(1) {
            observer.status(&Status {
                t: r.t,
                rate_hz: window_cycles as f64 / last_status.elapsed().as_secs_f64(),
                horizon_s: r.horizon_s,
                sample_age_s: r.sample_age_s,
                command_delay_s: r.command_delay_s,
                deviation_max_m: window_max * 1e-3,
                mode: r.mode,
            });
            last_status = Instant::now();
            (window_cycles, window_max) = (0, 0.0);
        }
    }
    // The loop has ended: the notes of its last cycles.
    session.drain(&mut s, observer);
    observer.finish();
    if let Some(w) = w.as_mut()
        && log_error.is_none()
        && let Err(e) = w.flush()
    {
        log_error = Some(e.into());
    }
    s.log_error = log_error.map(|e| e.to_string());
    s
}

/// How the run's final stop went, as it happened.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum StopOutcome {
    /// stopj was sent and the arm stood still after `after_s`.
    Standstill {
        /// Seconds from the stop to standstill.
        after_s: f64,
    },
    /// stopj was refused (the robot had stopped itself: a fault, a lost program), and the arm
    /// stands still.
    AlreadyStopped {
        /// Why stopj was refused.
        why: String,
    },
    /// The arm was still moving `after_s` after the stop (stopj sent, or refused for `refused`).
    StillMoving {
        /// Seconds waited.
        after_s: f64,
        /// Why stopj was refused, if it was.
        refused: Option<String>,
    },
}

impl std::fmt::Display for StopOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Standstill { after_s } => {
                write!(f, "stopj sent, standstill after {after_s:.2} s")
            }
            Self::AlreadyStopped { why } => {
                write!(f, "stopj refused ({why}); the arm stands still")
            }
            Self::StillMoving {
                after_s,
                refused: None,
            } => write!(
                f,
                "stopj sent, but the arm still moved after {after_s:.1} s"
            ),
            Self::StillMoving {
                after_s,
                refused: Some(why),
            } => write!(
                f,
                "stopj refused ({why}), and the arm still moved after {after_s:.1} s"
            ),
        }
    }
}

/// The run's summary (`mocomp run --json` prints it): what an operator, and
/// `scripts/stress.sh`, reads. Times in ms or µs and deviations in mm, as the field names say.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunReport {
    /// Cycles run.
    pub cycles: u64,
    /// From the first cycle to the last, s.
    pub seconds: f64,
    /// Cycles per second.
    pub rate_hz: f64,
    /// Robot periods without a cycle.
    pub missed_cycles: u64,
    /// Of all periods.
    pub missed_percent: f64,
    /// Records the logger could not take (it fell behind); the loop never waits for it.
    pub log_records_dropped: u64,
    /// Cycle period, median.
    pub period_median_ms: f64,
    /// Cycle period, 99th percentile.
    pub period_p99_ms: f64,
    /// Cycle period, largest.
    pub period_max_ms: f64,
    /// Cycle compute (the socket write included), median.
    pub compute_median_us: f64,
    /// The same, 99th percentile.
    pub compute_p99_us: f64,
    /// The same, largest.
    pub compute_max_us: f64,
    /// From the cycle's start to its command, median.
    pub command_delay_median_ms: f64,
    /// Share of cycles tracking.
    pub tracking_percent: f64,
    /// Share of cycles approaching along a planned path.
    pub approaching_percent: f64,
    /// Share of cycles holding.
    pub holding_percent: f64,
    /// Share of cycles faulted.
    pub faulted_percent: f64,
    /// Share of cycles retreating.
    pub retreating_percent: f64,
    /// Goal deviation while tracking, RMS.
    pub deviation_rms_mm: f64,
    /// The same, 95th percentile.
    pub deviation_p95_mm: f64,
    /// The same, largest.
    pub deviation_max_mm: f64,
    /// Rotation deviation while tracking, 95th percentile, degrees.
    pub rotation_p95_deg: f64,
    /// Holds, for any reason.
    pub holds: usize,
    /// Holds for a stale robot state.
    pub robot_stale_holds: usize,
    /// The controller's protective stops (each counted once, however often its hold was
    /// entered before the operator's re-arm).
    pub protective_stops: usize,
    /// The contact force read (`loop.force_sensing`), RMS, N (NaN without it).
    pub contact_force_n_rms: f64,
    /// The same, largest.
    pub contact_force_n_max: f64,
    /// Retreats for a force rule (over the limit, over the warning level too long, a stale or
    /// saturated sensor).
    pub force_retreats: usize,
    /// Events.
    pub events: usize,
    /// Each event: loop time (s) and what happened.
    pub event_log: Vec<(f64, String)>,
    /// The mode at the end.
    pub final_mode: String,
    /// How the final stop went.
    pub stop: StopOutcome,
    /// Why the CSV log stopped being written, if it did.
    pub log_error: Option<String>,
    /// What real-time scheduling the loop got.
    pub realtime: String,
    /// Whether it got all it asked for.
    pub realtime_complete: bool,
    /// The session: pulses, the gate, the drift monitor.
    pub session: SessionReport,
    /// The ROS 2 node's messages published, and those it could not take in time (`None`:
    /// no node).
    pub ros2: Option<Ros2Figures>,
    /// The MCAP recording (`None`: none asked).
    pub record: Option<crate::ros2::RecordOutcome>,
    /// The depth camera's figures (`None`: the tracker is not a depth camera).
    pub camera: Option<crate::camera::CameraReport>,
    /// The tracker's OpenIGTLink connection (`None`: the head's poses came over ROS 2).
    pub tracker: Option<TrackerFigures>,
}

/// What the tracker's OpenIGTLink connection went through.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct TrackerFigures {
    /// Connections made (more than one: it was lost and made again).
    pub connections: u64,
    /// Head poses received.
    pub poses: u64,
    /// Messages dropped for a CRC mismatch or a bad layout.
    pub messages_dropped: u64,
    /// Streams dropped for a bad header (the client connected again).
    pub streams_dropped: u64,
    /// Messages stamped before the one before them (read at their arrival).
    pub backwards_timestamps: u64,
    /// Steps of the tracker's clock the client re-based for (`timestamps = "estimated"`).
    pub clock_steps: u64,
}

impl From<mocomp_igtl::client::ClientCounters> for TrackerFigures {
    fn from(c: mocomp_igtl::client::ClientCounters) -> Self {
        Self {
            connections: c.connections,
            poses: c.poses,
            messages_dropped: c.crc_errors + c.malformed,
            streams_dropped: c.fatal_errors,
            backwards_timestamps: c.backwards_timestamps,
            clock_steps: c.clock_steps,
        }
    }
}

/// What the ROS 2 node did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Ros2Figures {
    /// Messages published.
    pub published: u64,
    /// Messages the node could not take in time (dropped, never waited for).
    pub dropped: u64,
}

impl RunReport {
    fn new(
        s: &mut Summary,
        rt: Option<&mocomp_rt::RtReport>,
        final_mode: &Mode,
        stop: StopOutcome,
        session: SessionReport,
    ) -> Self {
        let span = s.last_t - s.first_t.unwrap_or(s.last_t);
        let n = s.cycles.max(1) as f64;
        let rms = (s.deviation_mm.iter().map(|d| d * d).sum::<f64>()
            / s.deviation_mm.len().max(1) as f64)
            .sqrt();
        let holds = |f: fn(&Reason) -> bool| {
            s.events
                .iter()
                .filter(|(_, e)| matches!(e, Event::Hold(r) if f(r)))
                .count()
        };
        Self {
            cycles: s.cycles,
            seconds: span,
            rate_hz: s.cycles.saturating_sub(1) as f64 / span.max(1e-9),
            missed_cycles: s.missed,
            missed_percent: 100.0 * s.missed as f64 / (s.cycles + s.missed).max(1) as f64,
            log_records_dropped: s.dropped,
            period_median_ms: percentile(&mut s.period_ms, 0.5),
            period_p99_ms: percentile(&mut s.period_ms, 0.99),
            period_max_ms: percentile(&mut s.period_ms, 1.0),
            compute_median_us: percentile(&mut s.compute_us, 0.5),
            compute_p99_us: percentile(&mut s.compute_us, 0.99),
            compute_max_us: percentile(&mut s.compute_us, 1.0),
            command_delay_median_ms: percentile(&mut s.delay_ms, 0.5),
            tracking_percent: 100.0 * s.by_mode[0] as f64 / n,
            approaching_percent: 100.0 * s.by_mode[1] as f64 / n,
            holding_percent: 100.0 * s.by_mode[2] as f64 / n,
            faulted_percent: 100.0 * s.by_mode[3] as f64 / n,
            retreating_percent: 100.0 * s.by_mode[4] as f64 / n,
            deviation_rms_mm: rms,
            deviation_p95_mm: percentile(&mut s.deviation_mm, 0.95),
            deviation_max_mm: percentile(&mut s.deviation_mm, 1.0),
            rotation_p95_deg: percentile(&mut s.deviation_deg, 0.95),
            holds: holds(|_| true),
            robot_stale_holds: holds(|r| matches!(r, Reason::RobotStale)),
            protective_stops: protective_stops(&s.events),
            contact_force_n_rms: if s.contact_force_n.is_empty() {
                f64::NAN
            } else {
                (s.contact_force_n.iter().map(|f| f * f).sum::<f64>()
                    / s.contact_force_n.len() as f64)
                    .sqrt()
            },
            contact_force_n_max: percentile(&mut s.contact_force_n, 1.0),
            force_retreats: s
                .events
                .iter()
                .filter(|(_, e)| {
                    matches!(e, Event::Retreat(r) if mocomp_control::force::is_force_reason(r))
                })
                .count(),
            events: s.events.len(),
            event_log: {
                let mut log: Vec<(f64, String)> = s
                    .events
                    .iter()
                    .map(|(t, e)| (*t, format!("{e:?}")))
                    .chain(s.session_lines.iter().cloned())
                    .collect();
                log.sort_by(|a, b| a.0.total_cmp(&b.0));
                log
            },
            final_mode: mode_name(final_mode),
            stop,
            log_error: s.log_error.clone(),
            realtime: rt.map_or_else(|| "normal scheduling".into(), mocomp_rt::RtReport::describe),
            realtime_complete: rt.is_some_and(mocomp_rt::RtReport::complete),
            session,
            ros2: None,
            record: None,
            camera: None,
            tracker: None,
        }
    }

    /// What went wrong at the end, which fails the run although the loop ran: a robot that did
    /// not stop, a cycle log left incomplete.
    pub fn failure(&self, log_csv: Option<&Path>) -> Option<String> {
        if let StopOutcome::StillMoving { .. } = &self.stop {
            return Some(format!("the robot did not stop: {}", self.stop));
        }
        if let Some(e) = &self.session.pulse_log_error {
            return Some(format!("the pulse log is incomplete: {e}"));
        }
        if let Some(e) = self.record.as_ref().and_then(|r| r.error.as_ref()) {
            return Some(format!("the recording is incomplete: {e}"));
        }
        self.log_error.as_ref().map(|e| {
            format!(
                "the cycle log {} is incomplete: {e}",
                log_csv
                    .map(Path::display)
                    .map(|d| d.to_string())
                    .unwrap_or_default()
            )
        })
    }
}

/// The live pace: a cycle per new robot state, on the monotonic clock, until stopped.
struct Live<'a> {
    robot: UrRobot,
    /// The head's poses: OpenIGTLink, or the ROS 2 node's topic.
    source: Box<dyn PoseSource>,
    /// Hold and resume called over ROS 2.
    ros2_calls: Option<Receiver<mocomp_ros2::node::Call>>,
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

impl crate::driver::Pace for Live<'_> {
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

    fn cycle_done(&mut self, record: CycleRecord) -> Result<(), Self::Error> {
        self.faulted = matches!(record.mode, Mode::Faulted(_));
        self.session.after_cycle(&record, &mut self.robot);
        if let Err(TrySendError::Full(_)) = self.tx.try_send(record) {
            self.dropped += 1;
        }
        Ok(())
    }

    fn requests(&mut self) -> Requests {
        if let Some(Ok(call)) = self.ros2_calls.as_ref().map(Receiver::try_recv) {
            match call {
                mocomp_ros2::node::Call::Hold => self.controls.set_hold(true),
                mocomp_ros2::node::Call::Resume => self.controls.resume(),
            }
        }
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

/// Runs the loop on `setup` until `controls` asks it to stop or `duration_s`, then stops the
/// robot and returns the report. `log_csv`: every cycle's record. `progress` is told what
/// starts; the `observer`, what happens while the loop runs.
pub fn run(
    setup: &Setup,
    log_csv: Option<&Path>,
    controls: &Controls,
    observer: Box<dyn Observer>,
    progress: &mut dyn Write,
) -> Result<RunReport, AppError> {
    let (model, arm) = (setup.model, setup.arm);
    let period = model.spec().series.period_s();
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
    // The ROS 2 node (its DDS participant takes a moment): before the robot is connected. It
    // publishes what an observer on the logger's thread gives it.
    let (ros2, ros2_calls) = match crate::ros2::start(setup)? {
        Some(link) => (Some(link.bridge), Some(link.calls)),
        None => (None, None),
    };
    let (observer, record_slot): (Box<dyn Observer>, _) =
        if ros2.is_some() || setup.file.record_mcap.is_some() {
            let (ros, slot) = crate::ros2::RosObserver::new(setup, ros2.clone())?;
            (Box::new(Both(observer, ros)), slot)
        } else {
            (observer, None)
        };
    // The session: its notes go to the logger too, which writes the pulse log (opened now, so a
    // path that cannot be written stops the run before the robot moves).
    let session_setup = SessionSetup::from_setup(setup)?;
    let (notes_tx, notes_rx) = sync_channel::<Note>(1024);
    let publisher: crate::live_session::Publisher = Arc::new(OnceLock::new());
    let mut session_side = SessionSide {
        notes: notes_rx,
        log: SessionLog::open(&session_setup, Arc::clone(&publisher))?,
    };
    // The loop's clock, once the world has made it.
    let loop_clock: Arc<OnceLock<Arc<dyn Clock>>> = Arc::new(OnceLock::new());
    let logger_clock = Arc::clone(&loop_clock);
    let log_thread = std::thread::Builder::new()
        .name("mocomp-log".into())
        .spawn(move || {
            // Whatever the thread that starts it runs at, the logger must not compete with the
            // real-time loop, nor sit on its core.
            mocomp_rt::set_normal().ok();
            mocomp_rt::unpin().ok();
            let mut observer = observer;
            let s = logger(
                rx,
                period,
                csv,
                &logger_clock,
                observer.as_mut(),
                &mut session_side,
            );
            session_side.log.finish();
            (s, session_side.log.report)
        })
        .what(|| "starting the logger thread")?;

    let cfg_rearm_s = cfg.params.robot_rearm_after_s;
    let mut comp = Compensator::new(cfg, arm, period);

    let file = &setup.file;
    let world = World::connect(setup, q0, progress, Some(&file.realtime))?;
    let realtime = world.realtime.clone();
    if let Some(w) = realtime.as_ref().and_then(mocomp_rt::RtReport::warning) {
        writeln!(progress, "warning: {w}").what(|| "writing the progress")?;
    }
    let clock = Arc::clone(&world.clock);
    if let Some(c) = &world.camera {
        c.notify(notes_tx.clone(), Arc::clone(&clock));
    }
    // Set once, here: it cannot have been set before.
    loop_clock.set(Arc::clone(&clock)).ok();
    if let Some(v) = &world.vision {
        controls.attach_vision(Arc::clone(v));
    }
    let ros2_head = file.tracker.source == crate::config::TrackerSource::Ros2;
    let client = (!ros2_head).then(|| world.client(setup, &file.tracker.device));
    // The session's own OpenIGTLink connection: the drift marker's poses, the pulses the server
    // announces, the gate published back.
    let session_client = (session_setup.marker.is_some() || session_setup.igtl_device.is_some())
        .then(|| {
            let device = session_setup
                .marker
                .as_ref()
                .map_or(file.tracker.device.as_str(), |m| m.0.as_str());
            // Pulses over OpenIGTLink only without a pulse input (one source of pulses).
            let by_message =
                session_setup.igtl_device.is_some() && session_setup.params.pulse_input.is_none();
            let keep = if by_message { 256 } else { 0 };
            world.client_keeping(setup, device, keep)
        });
    // The simulators (the rest of `world`) stay up until the end of this function.
    let mut robot = world.robot;
    if file.robot.zero_force_sensor {
        robot
            .zero_force_sensor()
            .what(|| "robot.zero_force_sensor")?;
        writeln!(progress, "force/torque sensor zeroed").what(|| "writing the progress")?;
    }
    let source: Box<dyn PoseSource> = match (&client, &ros2) {
        (Some(c), _) => Box::new(c.pose_source()),
        (None, Some(bridge)) => Box::new(bridge.head_source(Arc::clone(&clock))),
        (None, None) => refuse!("tracker.source = \"ros2\" without the ROS 2 node"),
    };
    let (session_client, messages) = match session_client {
        Some(c) => {
            let m = c.take_messages();
            (Some(Arc::new(c)), m)
        }
        None => (None, None),
    };
    let (pulses_tx, pulses_rx) = sync_channel::<f64>(64);
    let forwarding = Arc::new(AtomicBool::new(false));
    if let (Some(c), Some(_)) = (&session_client, &session_setup.igtl_device) {
        publisher.set(Arc::clone(c)).ok();
    }
    let forwarder = match (&session_client, messages) {
        (Some(_), Some(rx)) if session_setup.params.pulse_input.is_none() => {
            let stop = Arc::clone(&forwarding);
            Some(
                std::thread::Builder::new()
                    .name("mocomp-pulses".into())
                    .spawn(move || {
                        mocomp_rt::set_normal().ok();
                        mocomp_rt::unpin().ok();
                        crate::live_session::forward_pulses(&rx, &pulses_tx, &stop);
                    })
                    .what(|| "starting the pulse listener")?,
            )
        }
        _ => None,
    };
    let loop_session = LoopSession::new(
        &session_setup,
        setup,
        session_client
            .as_ref()
            .filter(|_| session_setup.marker.is_some())
            .map(|c| c.pose_source()),
        forwarder.is_some().then_some(pulses_rx),
        notes_tx,
    );
    controls.attach_targets(Arc::new(session_setup.targets.clone()));
    let start_goal = session_setup
        .start
        .and_then(|i| session_setup.targets.get(i))
        .map(|t| t.1);
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
        ros2_calls,
        session: loop_session,
        start_goal,
        held: false,
        guided: false,
        t_end,
        patience: Duration::from_secs_f64(3.0 * period),
        tx: &tx,
        dropped: 0,
        resumes_seen: controls.resumes(),
        faulted: false,
        rearm: false,
        stream_dead_s: cfg_rearm_s,
    };
    pace.start(period);
    // The live pace never fails: a late or missing state is the supervisor's to judge.
    match crate::driver::drive(&mut comp, &mut pace) {
        Ok(()) => {}
        Err(never) => match never {},
    }
    let Live {
        mut robot,
        dropped,
        mut session,
        ..
    } = pace;
    session.close(&mut robot);
    // Stop the robot in a defined way, and wait for standstill.
    let decel = comp.config().params.stop_decel_rad_s2;
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
    // At once: the logger's and the session's ends below may take longer than the watchdog.
    // The robot stands still (or the report says it does not): a failed close changes nothing.
    robot.close().ok();
    let after_s = t_stop.elapsed().as_secs_f64();
    let stop = match (sent, still) {
        (Ok(_), true) => StopOutcome::Standstill { after_s },
        (Err(e), true) => StopOutcome::AlreadyStopped { why: e.to_string() },
        (sent, false) => StopOutcome::StillMoving {
            after_s,
            refused: sent.err().map(|e| e.to_string()),
        },
    };
    let final_mode = comp.mode();
    forwarding.store(true, Ordering::Relaxed);
    if let Some(f) = forwarder {
        f.join().ok();
    }
    drop(tx);
    drop(session);
    let (mut s, session_report) = log_thread
        .join()
        .map_err(|_| AppError::Refused("the logger thread panicked".into()))?;
    s.dropped = dropped;
    let tracker = client.as_ref().map(|c| TrackerFigures::from(c.counters()));
    drop(client);
    drop(session_client);
    let mut report = RunReport::new(&mut s, realtime.as_ref(), &final_mode, stop, session_report);
    report.record =
        record_slot.and_then(|s| s.lock().unwrap_or_else(PoisonError::into_inner).take());
    report.ros2 = ros2.map(|b| Ros2Figures {
        published: b.published(),
        dropped: b.dropped(),
    });
    report.tracker = tracker;
    report.camera = world
        .camera
        .as_ref()
        .map(crate::camera::CameraServer::report);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::{Event, Reason, protective_stops};

    #[test]
    fn a_protective_stop_is_counted_once_until_the_rearm() {
        let stop = Event::Hold(Reason::Robot(mocomp_ur::RobotFault::ProtectiveStop));
        let ev = [
            (1.0, stop),
            (2.0, Event::Hold(Reason::RobotStale)),
            (2.1, stop),
            (3.0, Event::Rearmed),
            (4.0, stop),
        ];
        assert_eq!(protective_stops(&ev), 2);
    }
}
