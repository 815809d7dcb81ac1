//! The live loop's logger, on its own thread: each cycle's record from the loop's bounded
//! channel into the CSV log, to an [`Observer`] (each cycle, each event, the status once a
//! second) and into the figures of the [`RunReport`], with the session's notes. Nothing here
//! runs on the loop's thread.

use crate::frontend::{Observer, Status, mode_name, note_time};
use crate::live::session::SessionReport;
use crate::live::session_link::SessionLogSide;
use mocomp_control::{CycleRecord, Event, Mode, Reason};
use mocomp_geom::Clock;
use std::path::Path;
use std::sync::mpsc::Receiver;
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

/// An observer that writes the status and the events to its writer, one line each (`mocomp
/// run` without `--quiet`, on standard error). A line that cannot be written is dropped: the
/// loop never waits on a terminal.
#[derive(Debug, Clone, Copy, Default)]
pub struct Lines<W>(pub W);

impl<W: std::io::Write + Send> Observer for Lines<W> {
    fn event(&mut self, t: f64, e: &Event) {
        let _ = writeln!(self.0, "{t:9.3} s  {e}");
    }
    fn session(&mut self, t: f64, text: &str) {
        let _ = writeln!(self.0, "{t:9.3} s  session: {text}");
    }
    fn status(&mut self, s: &Status) {
        let _ = writeln!(
            self.0,
            "{:9.3} s  {:.0} Hz  horizon {:.1} ms (sample age {:.1} + command delay {:.1} + lookahead)  deviation max {:.2} mm  {}",
            s.t,
            s.rate_hz,
            s.horizon_s * 1e3,
            s.sample_age_s * 1e3,
            s.command_delay_s * 1e3,
            s.deviation_max_m * 1e3,
            mode_name(&s.mode)
        );
    }
}

/// What a recording left: its messages and why it stopped, if it did.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct RecordOutcome {
    /// The file.
    pub path: String,
    /// Messages written.
    pub messages: u64,
    /// Why the recording stopped early or could not be closed (the run then fails).
    pub error: Option<String>,
}

/// What the logger keeps for the summary.
#[derive(Debug, Default)]
pub(crate) struct Summary {
    cycles: u64,
    /// Records the loop could not queue (the logger fell behind).
    pub(crate) dropped: u64,
    first_t: Option<f64>,
    last_t: f64,
    /// The controller's time of the last cycle's state (NaN: none).
    last_robot_s: f64,
    missed: u64,
    /// Cycles run on a state an earlier cycle had answered (none newer came within the loop's
    /// patience): cycles of the loop's, not the controller's.
    repeated: u64,
    period_ms: Vec<f64>,
    compute_us: Vec<f64>,
    delay_ms: Vec<f64>,
    deviation_mm: Vec<f64>,
    deviation_deg: Vec<f64>,
    /// The contact force read each cycle (with `force_sensing`), N.
    contact_force_n: Vec<f64>,
    /// The dose's error while tracking (with a coil model), |dose − planned|, % of the planned.
    dose_error_pct: Vec<f64>,
    by_mode: [u64; 5],
    /// Cycles a rule (not the operator) held, stopped or backed the coil off, and the last
    /// such rule: why a run that never reached its goal did not.
    held_by_rule: u64,
    last_rule: Option<Reason>,
    events: Vec<(f64, Event)>,
    /// The session's notes, in words, and whether each is a pulse's (the pulse log has every
    /// pulse; the text summary counts them rather than listing them).
    session_lines: Vec<(f64, String, bool)>,
    /// Why the CSV log stopped being written, if it did.
    log_error: Option<String>,
}

impl Summary {
    /// A cycle in `mode`: by kind, and whether a rule (not the operator) kept the coil off.
    fn count_mode(&mut self, mode: &Mode) {
        self.by_mode[mode.kind()] += 1;
        if let Mode::Holding(why) | Mode::Faulted(why) | Mode::Retreating(why) = *mode
            && !matches!(why, Reason::Operator | Reason::HandGuided)
        {
            self.held_by_rule += 1;
            self.last_rule = Some(why);
        }
    }
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

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

/// The session's notes waiting on the logger's thread: into its log, to the observer, into the
/// summary. The log's pulses get their UTC time from the loop's `clock`, tied to the system's
/// clock the first time it is known.
fn drain(
    session: &mut SessionLogSide,
    s: &mut Summary,
    observer: &mut dyn Observer,
    clock: &OnceLock<Arc<dyn Clock>>,
) {
    if !session.log.has_utc_offset()
        && let Some(c) = clock.get()
        && let Ok(unix) = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH)
    {
        session.log.set_utc_offset(unix.as_secs_f64() - c.now_s());
    }
    while let Ok(n) = session.notes.try_recv() {
        let t = note_time(&n);
        let line = session.log.take(&n);
        observer.note(&n);
        observer.session(t, &line);
        s.session_lines
            .push((t, line, matches!(n, crate::frontend::Note::Pulse(..))));
    }
}

/// Controller cycles between two consecutive cycles of the loop that it did not answer: by the
/// controller's times of the states they answered (`robot_s`, previous and this), else by the
/// loop's own (`t`). The loop's clock alone overcounts: states a controller sends late and then
/// in a burst leave a gap in when the loop ran although it answered every one of them.
fn unanswered(robot_s: (f64, f64), t: (f64, f64), period: f64) -> u64 {
    let gap = if robot_s.0.is_finite() && robot_s.1.is_finite() {
        robot_s.1 - robot_s.0
    } else {
        t.1 - t.0
    };
    if gap > 1.5 * period {
        (gap / period).round() as u64 - 1
    } else {
        0
    }
}

/// This cycle's state is the one the last cycle answered (by the controller's time of it): the
/// loop waited its patience for a newer one and cycled anyway to keep the controller's watchdog
/// fed. A controller restarted from zero sends new states whose times repeat none.
fn answered_again(last_robot_s: f64, robot_s: f64) -> bool {
    last_robot_s.is_finite() && robot_s == last_robot_s
}

pub(crate) fn logger(
    rx: Receiver<CycleRecord>,
    period: f64,
    csv: Option<std::fs::File>,
    clock: &OnceLock<Arc<dyn Clock>>,
    observer: &mut dyn Observer,
    session: &mut SessionLogSide,
) -> Summary {
    let mut s = Summary::default();
    let mut w = csv.map(csv::Writer::from_writer);
    // A log that cannot be written (a full disk) is not dropped silently: it stops logging, and
    // the run reports it and fails once the robot is stopped.
    let mut log_error: Option<csv::Error> = None;
    if let Some(w) = w.as_mut()
        && let Err(e) = w.write_record(CSV_HEADER)
    {
        log_error = Some(e);
    }
    let mut last_status = Instant::now();
    // Since the last status line: cycles and the largest deviation while tracking (mm).
    let (mut window_cycles, mut window_max) = (0u64, 0.0f64);
    for r in rx {
        observer.cycle(&r, clock.get().map_or(f64::NAN, |c| c.now_s() - r.t));
        window_cycles += 1;
        if let Some(dev_mm) = tally(&mut s, &r, period) {
            window_max = window_max.max(dev_mm);
        }
        if let Some(e) = r.event {
            s.events.push((r.t, e));
            observer.event(r.t, &e);
        }
        drain(session, &mut s, observer, clock);
        if let Some(w) = w.as_mut().filter(|_| log_error.is_none()) {
            let row = csv_row(&r);
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
    drain(session, &mut s, observer, clock);
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

/// The cycle log's columns.
const CSV_HEADER: [&str; 29] = [
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
    "dose_v_per_m",
    "dose_pct",
];

/// One cycle into the run's statistics; its deviation (mm) when it was tracking.
fn tally(s: &mut Summary, r: &CycleRecord, period: f64) -> Option<f64> {
    s.cycles += 1;
    if s.first_t.is_none() {
        s.first_t = Some(r.t);
    } else {
        s.period_ms.push((r.t - s.last_t) * 1e3);
        s.missed += unanswered((s.last_robot_s, r.robot_s), (s.last_t, r.t), period);
        if answered_again(s.last_robot_s, r.robot_s) {
            s.repeated += 1;
        }
    }
    s.last_t = r.t;
    s.last_robot_s = r.robot_s;
    s.count_mode(&r.mode);
    s.compute_us.push(r.compute_ns as f64 / 1e3);
    s.delay_ms.push(r.command_delay_s * 1e3);
    // The measured flange against the goal for the head estimated at the same time (not the
    // goal the command aims at, which is the head predicted a horizon ahead).
    let (dev_mm, dev_deg) = (r.deviation.0 * 1e3, r.deviation.1.to_degrees());
    if r.mode == Mode::Tracking && dev_mm.is_finite() {
        s.deviation_mm.push(dev_mm);
        s.deviation_deg.push(dev_deg);
    }
    if r.contact_force_n.is_finite() {
        s.contact_force_n.push(r.contact_force_n);
    }
    if r.mode == Mode::Tracking && r.dose_pct.is_finite() {
        s.dose_error_pct.push((r.dose_pct - 100.0).abs());
    }
    let tracked = r.mode == Mode::Tracking && dev_mm.is_finite();
    tracked.then_some(dev_mm)
}

/// One cycle's row of the log.
fn csv_row(r: &CycleRecord) -> Vec<String> {
    let (path, _) = r.path.unwrap_or((f64::NAN, f64::NAN));
    let (dev_mm, dev_deg) = (r.deviation.0 * 1e3, r.deviation.1.to_degrees());
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
        format!("{:.3}", r.dose_v_per_m),
        format!("{:.3}", r.dose_pct),
    ]);
    row
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
    /// Controller cycles the loop did not answer (counted on the controller's clock, so a state
    /// that came late and was answered is not one).
    pub missed_cycles: u64,
    /// Of all periods.
    pub missed_percent: f64,
    /// Cycles run on a state an earlier cycle had already answered (no newer one came within the
    /// loop's patience, so it resent its command rather than let the controller's watchdog
    /// starve): counted in `cycles`, so `cycles − repeated_cycles + missed_cycles` is the
    /// controller's cycles over the run.
    pub repeated_cycles: u64,
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
    /// The dose's error against the planned while tracking, |dose − planned| in % of the
    /// planned (`[coil] model`), RMS (NaN without a coil model or a cycle tracked).
    pub dose_error_pct_rms: f64,
    /// The same, 95th percentile.
    pub dose_error_pct_p95: f64,
    /// The same, largest.
    pub dose_error_pct_max: f64,
    /// The loop's events.
    pub events: usize,
    /// The session's notes other than pulses (the gate, the drift monitor, a target chosen).
    pub session_notes: usize,
    /// Each event and session note, pulses among them: loop time (s) and what happened (the
    /// loop's events by their code, `Hold(NoPath(0.156…))`, for scripts).
    pub event_log: Vec<(f64, String)>,
    /// The loop's events in words and the session's notes but pulses, by loop time (s): what
    /// the text summary lists.
    #[serde(skip)]
    pub event_words: Vec<(f64, String)>,
    /// Why the coil never reached its goal, where a rule held it off for most of the run
    /// (`None`: it reached it, or the run ended while it was still on its way).
    pub not_reached: Option<NotReached>,
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
    pub record: Option<RecordOutcome>,
    /// The depth camera's figures (`None`: the tracker is not a depth camera).
    pub camera: Option<crate::camera::CameraReport>,
    /// The tracker's OpenIGTLink connection (`None`: the head's poses came over ROS 2).
    pub tracker: Option<TrackerFigures>,
    /// What the built-in simulated controller saw: its events (a protective stop's cause among
    /// them) and the loop's closest setpoint to a jump (`None`: a real robot).
    pub simulator: Option<crate::world::SimulatorFigures>,
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
    /// Times the client's reader failed on a message (it dropped the connection and made it
    /// again).
    pub reader_failures: u64,
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
            reader_failures: c.reader_failures,
        }
    }
}

/// What the ROS 2 node did.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Ros2Figures {
    /// Messages published.
    pub published: u64,
    /// Messages the node could not take in time (dropped, never waited for).
    pub dropped: u64,
    /// Times the node's thread failed (a panic) and went on.
    pub failures: u64,
    /// The last of them, in words.
    pub last_failure: Option<String>,
}

impl RunReport {
    /// The summary as `mocomp run` prints it: text, one figure per line; `log`: the cycle log's
    /// path, if one was written.
    pub fn write_text(
        &self,
        out: &mut dyn std::io::Write,
        log: Option<&str>,
    ) -> std::io::Result<()> {
        self.write_timing(out)?;
        self.write_tracking(out)?;
        self.write_links(out)?;
        self.write_events(out)?;
        self.write_end(out, log)
    }

    /// The cycles, real time, the period, the modes, the compute time, the command's delay.
    fn write_timing(&self, out: &mut dyn std::io::Write) -> std::io::Result<()> {
        let r = self;
        writeln!(out, "\nsummary")?;
        writeln!(
            out,
            "  cycles            {} in {:.2} s ({:.1} Hz); missed {} ({:.2} %); on a state already answered {}; log records dropped {}",
            r.cycles,
            r.seconds,
            r.rate_hz,
            r.missed_cycles,
            r.missed_percent,
            r.repeated_cycles,
            r.log_records_dropped
        )?;
        writeln!(
            out,
            "  real time         {}{}",
            r.realtime,
            if r.realtime_complete {
                ""
            } else {
                " (the loop ran without full real-time scheduling)"
            }
        )?;
        writeln!(
            out,
            "  cycle period      median {:.3} ms, p99 {:.3} ms, max {:.3} ms",
            r.period_median_ms, r.period_p99_ms, r.period_max_ms
        )?;
        writeln!(
            out,
            "  modes             tracking {:.1} %, approaching {:.1} %, retreating {:.1} %, holding {:.1} %, faulted {:.1} %",
            r.tracking_percent,
            r.approaching_percent,
            r.retreating_percent,
            r.holding_percent,
            r.faulted_percent
        )?;
        writeln!(
            out,
            "  cycle compute     median {:.1} µs, p99 {:.1} µs, max {:.1} µs (the socket write included)",
            r.compute_median_us, r.compute_p99_us, r.compute_max_us
        )?;
        writeln!(
            out,
            "  command delay     median {:.2} ms",
            r.command_delay_median_ms
        )?;
        Ok(())
    }

    /// How well it tracked: deviation, dose, holds, the session's pulses.
    fn write_tracking(&self, out: &mut dyn std::io::Write) -> std::io::Result<()> {
        let r = self;
        writeln!(
            out,
            "  goal deviation    while tracking: RMS {:.2} mm, p95 {:.2} mm, max {:.2} mm; rotation p95 {:.2}°",
            r.deviation_rms_mm, r.deviation_p95_mm, r.deviation_max_mm, r.rotation_p95_deg
        )?;
        if r.dose_error_pct_rms.is_finite() {
            writeln!(
                out,
                "  dose error        while tracking: RMS {:.2} %, p95 {:.2} %, max {:.2} % of the planned",
                r.dose_error_pct_rms, r.dose_error_pct_p95, r.dose_error_pct_max
            )?;
        }
        writeln!(
            out,
            "  holds             {} (robot state stale {}, protective stops {})",
            r.holds, r.robot_stale_holds, r.protective_stops
        )?;
        let ses = &r.session;
        if ses.pulses > 0 || ses.gate_openings > 0 || !ses.drift_max_mm.is_nan() {
            writeln!(
                out,
                "  session           {} pulses ({} off target, largest error on target {:.2} mm), gate opened {} times{}",
                ses.pulses,
                ses.pulses_off_target,
                ses.pulse_error_max_mm,
                ses.gate_openings,
                if ses.calibration_invalid {
                    "; CALIBRATION NO LONGER VALID"
                } else {
                    ""
                }
            )?;
        }
        Ok(())
    }

    /// The depth camera's and the tracker link's figures, when there were any.
    fn write_links(&self, out: &mut dyn std::io::Write) -> std::io::Result<()> {
        let r = self;
        if let Some(c) = &r.camera {
            writeln!(
                out,
                "  depth camera      {} frames, marker in {}; {} dropped, {} incomplete; acquisition to pose {:.1} ms median, {:.1} ms p99",
                c.frames, c.found, c.dropped, c.incomplete, c.latency_median_ms, c.latency_p99_ms
            )?;
            if let (Some(e), Some(d)) = (&c.ended, &c.ended_detail) {
                writeln!(out, "    ended: {e} ({d})")?;
            }
        }
        if let Some(t) = &r.tracker {
            writeln!(
                out,
                "  tracker link      {} connections, {} poses; {} messages and {} streams dropped (damaged), {} clock steps re-based",
                t.connections, t.poses, t.messages_dropped, t.streams_dropped, t.clock_steps
            )?;
        }
        Ok(())
    }

    /// The loop's and the session's events, and the simulated robot's.
    fn write_events(&self, out: &mut dyn std::io::Write) -> std::io::Result<()> {
        let r = self;
        writeln!(
            out,
            "  events            {} of the loop, {} of the session{}",
            r.events,
            r.session_notes,
            if r.session.pulses > 0 {
                format!("; {} pulses, each in the pulse log", r.session.pulses)
            } else {
                String::new()
            }
        )?;
        for (t, e) in &r.event_words {
            writeln!(out, "    {t:9.3} s  {e}")?;
        }
        if let Some(sim) = &r.simulator {
            writeln!(
                out,
                "  simulated robot   fastest setpoint {:.0} % of a jump's speed (at {:.3} s); {} events",
                100.0 * sim.setpoint_peak_share,
                sim.setpoint_peak_s,
                sim.events.len()
            )?;
            for (t, e) in &sim.events {
                writeln!(out, "    {t:9.3} s  {e}")?;
            }
        }
        Ok(())
    }

    /// How it ended: the final mode, what was not reached, the robot's stop, the log.
    fn write_end(&self, out: &mut dyn std::io::Write, log: Option<&str>) -> std::io::Result<()> {
        let r = self;
        writeln!(out, "  final mode        {}", r.final_mode)?;
        if let Some(n) = &r.not_reached {
            writeln!(out, "  NOT REACHED       {n}")?;
        }
        writeln!(out, "  robot stop        {}", r.stop)?;
        if let Some(e) = &r.log_error {
            writeln!(out, "  log error         {e}")?;
        }
        if let Some(p) = log {
            writeln!(out, "  log               {p}")?;
        }
        Ok(())
    }

    pub(crate) fn new(
        s: &mut Summary,
        rt: Option<&mocomp_rt::RtReport>,
        final_mode: &Mode,
        stop: StopOutcome,
        session: SessionReport,
    ) -> Self {
        let span = s.last_t - s.first_t.unwrap_or(s.last_t);
        let n = s.cycles.max(1) as f64;
        // No cycle tracked: no figure (as the percentiles say), not the -0 of an empty sum.
        let rms = if s.deviation_mm.is_empty() {
            f64::NAN
        } else {
            (s.deviation_mm.iter().map(|d| d * d).sum::<f64>() / s.deviation_mm.len() as f64).sqrt()
        };
        let rms_of = |v: &[f64]| {
            if v.is_empty() {
                f64::NAN
            } else {
                (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
            }
        };
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
            missed_percent: 100.0 * s.missed as f64
                / (s.cycles - s.repeated + s.missed).max(1) as f64,
            repeated_cycles: s.repeated,
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
            contact_force_n_rms: rms_of(&s.contact_force_n),
            contact_force_n_max: percentile(&mut s.contact_force_n, 1.0),
            force_retreats: s
                .events
                .iter()
                .filter(|(_, e)| {
                    matches!(e, Event::Retreat(r) if mocomp_control::force::is_force_reason(r))
                })
                .count(),
            dose_error_pct_rms: rms_of(&s.dose_error_pct),
            dose_error_pct_p95: percentile(&mut s.dose_error_pct, 0.95),
            dose_error_pct_max: percentile(&mut s.dose_error_pct, 1.0),
            events: s.events.len(),
            session_notes: s.session_lines.iter().filter(|l| !l.2).count(),
            event_log: by_time(
                s.events
                    .iter()
                    .map(|(t, e)| (*t, format!("{e:?}")))
                    .chain(s.session_lines.iter().map(|(t, l, _)| (*t, l.clone()))),
            ),
            event_words: by_time(
                s.events
                    .iter()
                    .map(|(t, e)| (*t, e.to_string()))
                    .chain(
                        s.session_lines
                            .iter()
                            .filter(|l| !l.2)
                            .map(|(t, l, _)| (*t, l.clone())),
                    ),
            ),
            not_reached: NotReached::judge(s),
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
            simulator: None,
        }
    }

    /// What went wrong at the end, which fails the run although the loop ran: a robot that did
    /// not stop, a cycle log left incomplete, a goal a rule kept the coil from.
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
        if let Some(e) = &self.log_error {
            return Some(format!(
                "the cycle log {} is incomplete: {e}",
                log_csv
                    .map(Path::display)
                    .map(|d| d.to_string())
                    .unwrap_or_default()
            ));
        }
        self.not_reached.as_ref().map(ToString::to_string)
    }
}

/// Events and notes in the order of their loop time.
fn by_time(lines: impl Iterator<Item = (f64, String)>) -> Vec<(f64, String)> {
    let mut log: Vec<_> = lines.collect();
    log.sort_by(|a, b| a.0.total_cmp(&b.0));
    log
}

/// A run whose coil never reached its goal because a rule held it off: the rule in words, its
/// code and what to do. Not a run ended while the coil was still on its way (a short run, the
/// operator's stop): only one a rule held, stopped or backed off for most of its cycles.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct NotReached {
    /// The last rule that held it, in words.
    pub reason: String,
    /// The same, by its code (`NoPath(0.156…)`).
    pub code: String,
    /// Held, stopped or backed off by a rule: the share of the run's cycles, %.
    pub held_percent: u32,
    /// What to do about it.
    pub advice: Option<String>,
}

impl NotReached {
    fn judge(s: &Summary) -> Option<Self> {
        let reached = s.by_mode[0] > 0 || s.events.iter().any(|(_, e)| *e == Event::Reached);
        let rule = s.last_rule?;
        if reached || s.held_by_rule * 2 <= s.cycles {
            return None;
        }
        Some(Self {
            reason: rule.to_string(),
            code: format!("{rule:?}"),
            held_percent: (100 * s.held_by_rule / s.cycles.max(1)) as u32,
            advice: rule.advice().map(str::to_string),
        })
    }
}

impl std::fmt::Display for NotReached {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the coil never reached its goal: a rule held it off for {} % of the run, last: {}",
            self.held_percent, self.reason
        )?;
        if let Some(a) = &self.advice {
            write!(f, "; {a}")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::{
        Event, Reason, RunReport, StopOutcome, Summary, answered_again, protective_stops, tally,
        unanswered,
    };
    use crate::live::session::SessionReport;
    use mocomp_control::{CycleRecord, Mode};

    #[test]
    fn a_run_that_never_tracked_has_no_deviation_figure_and_one_that_did_has_its_rms() {
        let stop = || StopOutcome::Standstill { after_s: 0.1 };
        let mode = Mode::Approaching;
        let mut none = Summary::default();
        let r = RunReport::new(&mut none, None, &mode, stop(), SessionReport::default());
        assert!(r.deviation_rms_mm.is_nan(), "{}", r.deviation_rms_mm);
        let mut some = Summary {
            deviation_mm: vec![3.0, 4.0],
            ..Summary::default()
        };
        let r = RunReport::new(&mut some, None, &mode, stop(), SessionReport::default());
        assert!((r.deviation_rms_mm - 12.5f64.sqrt()).abs() < 1e-12);
    }

    /// States that came late and then in a burst were all answered: the controller's clock
    /// says so, however the loop's own clock bunched them. A state skipped is counted.
    #[test]
    fn missed_cycles_are_the_controllers_cycles_the_loop_did_not_answer() {
        let p = 0.002;
        // The controller's states 2 ms apart, the loop answering them 3.8 ms and 0.2 ms apart.
        let states = [0.100, 0.102, 0.104, 0.106, 0.108];
        let loop_t = [1.000, 1.0038, 1.0040, 1.0078, 1.0080];
        let counted = |robot: &[f64], t: &[f64]| -> u64 {
            (1..robot.len())
                .map(|k| unanswered((robot[k - 1], robot[k]), (t[k - 1], t[k]), p))
                .sum()
        };
        assert_eq!(counted(&states, &loop_t), 0);
        // Without the controller's clock, the loop's gaps are all there is to count.
        let none = [f64::NAN; 5];
        assert_eq!(counted(&none, &loop_t), 2);
        // The state at 0.104 never answered; the one at 0.106 answered twice (no state came).
        assert_eq!(
            counted(&[0.100, 0.102, 0.106, 0.106], &[1.0, 1.002, 1.006, 1.008]),
            1
        );
        // A controller restarted from zero is no gap.
        assert_eq!(unanswered((5.0, 0.002), (1.0, 1.002), p), 0);
    }

    /// A cycle the loop ran on a state it had answered (none newer within its patience) is one
    /// of the loop's cycles and none of the controller's: with the missed ones, the cycles on
    /// new states are the controller's, however the loop's patience ran out.
    #[test]
    fn cycles_on_a_state_already_answered_are_counted_apart_from_the_controllers() {
        let p = 0.002;
        // The controller's 8 cycles 0.100..0.114: the loop answers 0.100, 0.102, waits out its
        // patience twice on 0.102, answers 0.104, skips 0.106 and 0.108, answers 0.110..0.114.
        let robot = [0.100, 0.102, 0.102, 0.102, 0.104, 0.110, 0.112, 0.114];
        let mut s = Summary::default();
        for (k, robot_s) in robot.iter().enumerate() {
            let mut r = CycleRecord::new(1.0 + 0.002 * k as f64, Mode::Tracking, [0.0; 6]);
            r.robot_s = *robot_s;
            tally(&mut s, &r, p);
        }
        let report = RunReport::new(
            &mut s,
            None,
            &Mode::Tracking,
            StopOutcome::Standstill { after_s: 0.1 },
            SessionReport::default(),
        );
        assert_eq!(report.cycles, 8);
        assert_eq!(report.repeated_cycles, 2);
        assert_eq!(report.missed_cycles, 2);
        let controllers = report.cycles - report.repeated_cycles + report.missed_cycles;
        assert_eq!(controllers, 8);
        assert!(
            (report.missed_percent - 25.0).abs() < 1e-9,
            "{}",
            report.missed_percent
        );
        // Without the controller's clock nothing says a state repeated.
        assert!(!answered_again(f64::NAN, f64::NAN));
        assert!(!answered_again(f64::NAN, 0.1));
        assert!(answered_again(0.1, 0.1));
    }

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

    /// `modes`: (cycles, mode) in order, one cycle a count.
    fn run_of(modes: &[(u64, Mode)], events: &[(f64, Event)]) -> RunReport {
        let mut s = Summary::default();
        for (n, m) in modes {
            for _ in 0..*n {
                s.cycles += 1;
                s.count_mode(m);
            }
        }
        s.events = events.to_vec();
        let last = modes.last().map_or(Mode::Approaching, |m| m.1);
        let stop = StopOutcome::Standstill { after_s: 0.1 };
        RunReport::new(&mut s, None, &last, stop, SessionReport::default())
    }

    #[test]
    fn a_run_a_rule_kept_from_its_goal_fails_with_the_rule_in_words_and_what_to_do() {
        // F3 at the example placement: a short approach, then held for an unreachable goal,
        // a singular one, no path.
        let r = run_of(
            &[
                (50, Mode::Approaching),
                (900, Mode::Holding(Reason::Unreachable)),
                (800, Mode::Holding(Reason::Singular(0.0059))),
                (700, Mode::Holding(Reason::NoPath(0.156))),
            ],
            &[(0.4, Event::Hold(Reason::Unreachable))],
        );
        let why = r.failure(None).expect("a failed run");
        assert!(why.contains("never reached its goal"), "{why}");
        assert!(why.contains("97 %"), "{why}");
        assert!(why.contains("blocked 156 mm along it"), "{why}");
        assert!(why.contains("move the patient or the robot"), "{why}");
        let n = r.not_reached.as_ref().expect("not reached");
        assert_eq!(n.code, "NoPath(0.156)");
        let mut text = Vec::new();
        r.write_text(&mut text, None).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.contains("NOT REACHED       the coil never"), "{text}");
        assert!(
            text.contains("hold: the goal is out of the arm's reach"),
            "{text}"
        );
    }

    #[test]
    fn a_run_ended_on_its_way_held_by_the_operator_or_after_reaching_does_not_fail() {
        let on_its_way = run_of(&[(125, Mode::Approaching)], &[]);
        assert!(on_its_way.failure(None).is_none());
        // Mostly on its way, a moment held by a stale robot state (a loaded host).
        let stalled = run_of(
            &[
                (60, Mode::Approaching),
                (40, Mode::Holding(Reason::RobotStale)),
                (25, Mode::Approaching),
            ],
            &[],
        );
        assert!(stalled.failure(None).is_none());
        let operator = run_of(
            &[
                (10, Mode::Approaching),
                (990, Mode::Holding(Reason::Operator)),
            ],
            &[],
        );
        assert!(operator.failure(None).is_none());
        let reached = run_of(
            &[
                (100, Mode::Approaching),
                (10, Mode::Tracking),
                (900, Mode::Holding(Reason::MarkerInvalid)),
            ],
            &[(0.8, Event::Reached)],
        );
        assert!(reached.failure(None).is_none());
        // The same hold from the start, never reached: it fails, and says what to do.
        let never = run_of(&[(900, Mode::Holding(Reason::MarkerInvalid))], &[]);
        let why = never.failure(None).expect("a failed run");
        assert!(why.contains("tracker's view"), "{why}");
    }

    #[test]
    fn the_summary_counts_events_and_notes_apart_and_lists_no_pulse() {
        let mut s = Summary {
            cycles: 10,
            events: vec![(0.5, Event::Reached), (2.0, Event::Hold(Reason::Operator))],
            session_lines: vec![
                (1.0, "gate open on f3".into(), false),
                (
                    1.2,
                    "pulse on f3: 0.40 mm, 0.30 deg, gate open".into(),
                    true,
                ),
                (
                    1.4,
                    "pulse on f3: 0.42 mm, 0.31 deg, gate open".into(),
                    true,
                ),
            ],
            ..Summary::default()
        };
        let session = SessionReport {
            pulses: 2,
            ..SessionReport::default()
        };
        let stop = StopOutcome::Standstill { after_s: 0.1 };
        let r = RunReport::new(&mut s, None, &Mode::Tracking, stop, session);
        assert_eq!((r.events, r.session_notes), (2, 1));
        // The machine record keeps every line, codes for the loop's.
        assert_eq!(r.event_log.len(), 5);
        assert_eq!(r.event_log[0].1, "Reached");
        let mut text = Vec::new();
        r.write_text(&mut text, None).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(
            text.contains(
                "events            2 of the loop, 1 of the session; 2 pulses, each in the pulse log"
            ),
            "{text}"
        );
        assert!(!text.contains("pulse on"), "{text}");
        assert!(text.contains("reached the goal: tracking"), "{text}");
        assert!(text.contains("gate open on f3"), "{text}");
    }
}
