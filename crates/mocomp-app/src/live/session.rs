//! The clinical session in `mocomp run` (`[session]`): on the loop's thread, after each cycle,
//! the on-target gate on the cycle's measured coil (to a robot output), the pulses (a robot
//! input's rising edge, or a STRING `pulse` over OpenIGTLink) and the drift monitor on a marker
//! on the flange (the loop holds once it calls the calibration invalid), and, with a coil model
//! (`[coil] model`), the dose the measured coil gives at the goal's target, into the cycle's
//! record before the gate and the log see it; before each cycle, a target the operator
//! selected. What happened goes to the logger thread as [`Note`]s (`Copy`,
//! through a bounded channel the loop never waits on), which writes the pulse log, publishes the
//! gate over OpenIGTLink and keeps the figures.

use crate::config::Setup;
use crate::frontend::{NamedTargets, Note};
use crate::{AppError, Context};
use mocomp_control::CycleRecord;
use mocomp_efield::DosePlans;
use mocomp_geom::PoseSource;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_igtl::client::{Client, IgtlPoseSource};
use mocomp_igtl::message::Body;
use mocomp_session::{
    Announced, Drift, GateEvent, GateState, JointHistory, Session, Targets, shut_reason,
};
use mocomp_ur::{Robot, UrRobot};
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};

/// The session's configuration, resolved: the targets read, the start target found, the
/// drift monitor's marker known.
#[derive(Debug, Clone)]
pub struct SessionSetup {
    /// The targets (name, `head_from_coil`), in the file's order.
    pub targets: NamedTargets,
    /// The target the loop starts on, if one is named.
    pub start: Option<usize>,
    /// The gate, the drift monitor, the robot's I/O.
    pub params: mocomp_session::SessionParams,
    /// The pulse log's path.
    pub pulse_log: Option<PathBuf>,
    /// The OpenIGTLink device the gate is published as (and pulses are taken from the server).
    pub igtl_device: Option<String>,
    /// The drift monitor's marker: its device and flange_from_marker.
    pub marker: Option<(String, Isometry3<f64>)>,
    /// What a pulse's record is made with: the image, the head, the configured output (its
    /// UTC offset is set once the loop's clock runs).
    pub recorder: mocomp_session::Recorder,
    /// With a coil model: the dose planned for the configuration's goal and each target.
    pub dose: Option<DosePlans>,
}

impl SessionSetup {
    /// Resolves `[session]` of `setup`: reads the targets file, finds the start target, and the
    /// drift marker's mounting (the configured one, the calibration file's X, or the simulated
    /// tracker's). Errors name the key or the file.
    pub fn from_setup(setup: &Setup) -> Result<Self, AppError> {
        let s = &setup.file.session;
        let targets = match &s.targets {
            Some(f) => crate::navigation::targets::load(&setup.dir.join(f))?,
            None => Targets::default(),
        };
        let targets: Vec<_> = targets
            .targets
            .iter()
            .map(|t| {
                (
                    t.name.clone(),
                    crate::navigation::targets::head_from_coil(setup, t),
                )
            })
            .collect();
        let start = match &s.target {
            Some(name) => Some(targets.iter().position(|t| &t.0 == name).ok_or_else(|| {
                AppError::Config(format!(
                    "session.target {name:?}: not in {} (it has: {})",
                    s.targets.as_deref().unwrap_or_default(),
                    targets
                        .iter()
                        .map(|t| t.0.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })?),
            None => None,
        };
        let marker = match &s.marker_device {
            None => None,
            Some(device) => Some((device.clone(), flange_from_marker(setup)?)),
        };
        let recorder = mocomp_session::Recorder {
            utc_minus_loop_s: None,
            head_from_image: setup.file.head.head_from_image.iso(),
            head: setup.file.head_model()?,
            output_pct: s.stimulator_output_pct,
        };
        let dose = plan_doses(setup, &recorder.head, &targets)?;
        Ok(Self {
            targets,
            start,
            params: s.params(),
            pulse_log: s.pulse_log.as_ref().map(|p| setup.dir.join(p)),
            igtl_device: s.igtl_device.clone(),
            marker,
            recorder,
            dose,
        })
    }

    /// Whether `[session]` asks for anything: targets, the gate's output or its OpenIGTLink
    /// device, pulses, a pulse log, the drift monitor. Without, the gate is still judged (the
    /// loop does it for nothing) but not reported.
    pub fn active(&self) -> bool {
        !self.targets.is_empty()
            || self.params.gate_output.is_some()
            || self.params.pulse_input.is_some()
            || self.igtl_device.is_some()
            || self.pulse_log.is_some()
            || self.marker.is_some()
    }

    /// The target's name (`-` for the configuration's goal).
    pub fn name(&self, index: Option<usize>) -> &str {
        index
            .and_then(|i| self.targets.get(i))
            .map_or("-", |t| t.0.as_str())
    }
}

/// The dose planned on `head` for the configuration's goal (when it has one) and each of
/// `targets`, with `[coil] model` (`None` without). A target the model gives no dose at is
/// refused by name before anything moves.
fn plan_doses(
    setup: &Setup,
    head: &mocomp_control::HeadModel,
    targets: &NamedTargets,
) -> Result<Option<DosePlans>, AppError> {
    let Some(model) = setup.file.coil.dose_model()? else {
        return Ok(None);
    };
    let goal = setup.file.head_from_coil().ok();
    let poses: Vec<Isometry3<f64>> = targets.iter().map(|t| t.1).collect();
    DosePlans::new(&model, head.shape(), goal.as_ref(), &poses)
        .map(Some)
        .map_err(|e| {
            // The plan's error names a target by its number; the operator knows its name.
            let name = e
                .what
                .strip_prefix("the session's target ")
                .and_then(|k| k.parse::<usize>().ok())
                .and_then(|k| targets.get(k - 1))
                .map(|t| format!("target {:?}", t.0));
            AppError::Config(format!(
                "coil.model: the dose at {}: {}",
                name.unwrap_or(e.what.clone()),
                e.source
            ))
        })
}

/// The drift marker's mounting on the flange.
fn flange_from_marker(setup: &Setup) -> Result<Isometry3<f64>, AppError> {
    let file = &setup.file;
    if let Some(p) = &file.session.flange_from_marker {
        return Ok(p.iso());
    }
    if let Some(f) = &file.calibration.file {
        let path = setup.dir.join(f);
        let what = || {
            format!(
                "calibration.file {} (its X, for the drift monitor)",
                path.display()
            )
        };
        let text = std::fs::read_to_string(&path).what(what)?;
        let c = mocomp_calib::CalibrationFile::from_toml_str(&text).what(what)?;
        return Ok(c.transforms().what(what)?.0);
    }
    if file.tracker.source.simulated() {
        return Ok(file.tracker.simulated.flange_from_marker.iso());
    }
    Err(AppError::Config(
        "session.flange_from_marker: needed with session.marker_device (or calibration.file)"
            .into(),
    ))
}

/// The session on the loop's thread.
pub struct LoopSession {
    session: Session,
    /// The target selected (`None`: the configuration's goal).
    target: Option<usize>,
    marker: Option<(IgtlPoseSource, Isometry3<f64>)>,
    base_from_tracker: Isometry3<f64>,
    arm: mocomp_kin::Arm,
    history: JointHistory,
    /// Pulses announced over OpenIGTLink.
    pulses: Option<Receiver<Announced>>,
    gate_level: bool,
    /// Whether the gate's changes are reported ([`SessionSetup::active`]).
    report_gate: bool,
    notes: SyncSender<Note>,
    /// The dose's plans and meter (`None`: no coil model).
    dose: Option<DosePlans>,
    /// Notes the logger could not take.
    pub dropped: u64,
}

impl std::fmt::Debug for LoopSession {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LoopSession")
            .field("target", &self.target)
            .field("gate", &self.session.gate())
            .finish_non_exhaustive()
    }
}

impl LoopSession {
    /// The session of `s`, telling `notes`; `marker`: the drift marker's source (from its own
    /// OpenIGTLink client), `pulses`: pulses announced over OpenIGTLink.
    pub fn new(
        s: &SessionSetup,
        setup: &Setup,
        marker: Option<IgtlPoseSource>,
        pulses: Option<Receiver<Announced>>,
        notes: SyncSender<Note>,
    ) -> Self {
        Self {
            session: Session::new(s.params, (0.0, 0.0), s.start.unwrap_or(0)),
            target: s.start,
            marker: marker.zip(s.marker.as_ref().map(|m| m.1)),
            base_from_tracker: setup.base_from_tracker,
            arm: setup.arm,
            history: JointHistory::default(),
            pulses,
            gate_level: false,
            report_gate: s.active(),
            notes,
            dose: s.dose.clone(),
            dropped: 0,
        }
    }

    /// Tells the logger `n` (counted when it cannot take it).
    pub fn note(&mut self, n: Note) {
        if let Err(TrySendError::Full(_)) = self.notes.try_send(n) {
            self.dropped += 1;
        }
    }

    /// The operator selected target `index` (the loop is given its goal in the same cycle).
    pub fn select(&mut self, t: f64, index: usize) {
        self.session.select(index);
        self.target = Some(index);
        self.note(Note::Selected(t, index));
    }

    /// The calibration's offset once the drift monitor called it invalid.
    pub fn calibration_invalid(&self) -> Option<(f64, f64)> {
        self.session.calibration_invalid()
    }

    /// After the loop's cycle: the dose into its record, the drift monitor on the marker's new
    /// samples, the gate on the record (and the robot's output when it changed), the pulses.
    pub fn after_cycle(&mut self, rec: &mut CycleRecord, robot: &mut UrRobot) {
        measure_dose(self.dose.as_mut(), rec);
        let rec = &*rec;
        let state = robot.state();
        if let Some(s) = &state {
            self.history.push(s.received_s, s.actual_q);
        }
        if let Some((source, flange_from_marker)) = &mut self.marker {
            let mut changed = None;
            while let Some(s) = source.latest() {
                if let (true, Some(q)) = (s.valid, self.history.at(s.acquired_s)) {
                    let tracked = self.base_from_tracker * s.tracker_from_marker;
                    let by_robot = self.arm.fk_flange(&q) * *flange_from_marker;
                    changed = self
                        .session
                        .marker(s.acquired_s, &tracked, &by_robot)
                        .or(changed);
                }
            }
            if let Some(d) = changed {
                self.note(Note::Drift(rec.t, d));
            }
        }
        let step = self
            .session
            .cycle(rec, state.as_ref().map(|s| s.digital_inputs));
        if let Some(e) = step.gate_event.filter(|_| self.report_gate) {
            self.note(Note::Gate(rec.t, e, self.target));
        }
        if let Some(p) = step.pulse {
            self.note(Note::Pulse(p, self.target));
        }
        while let Some(a) = self.pulses.as_ref().and_then(|r| r.try_recv().ok()) {
            let p = self.session.pulse(&a);
            self.note(Note::Pulse(p, self.target));
        }
        if step.gate_open != self.gate_level
            && let Some(bit) = self.session.params().gate_output
        {
            if robot.set_digital_output(bit, step.gate_open).is_ok() {
                self.gate_level = step.gate_open;
            } else {
                self.note(Note::OutputFailed(rec.t));
            }
        }
    }

    /// The loop has ended: the gate output low again (the stimulator must not fire on a coil
    /// that nobody holds on target).
    pub fn close(&mut self, robot: &mut UrRobot) {
        if let Some(bit) = self.session.params().gate_output {
            robot.set_digital_output(bit, false).ok();
        }
    }
}

/// The dose the cycle's measured coil gives against the plan of the goal the loop holds, into
/// `rec` (NaN where there is no plan, coil or field).
pub fn measure_dose(plans: Option<&mut DosePlans>, rec: &mut CycleRecord) {
    if let (Some(d), Some(coil)) = (plans, rec.coil_now) {
        let m = d.dose_at_goal(&rec.head_from_coil_goal, &coil);
        (rec.dose_v_per_m, rec.dose_pct) = (m.v_per_m, m.pct);
    }
}

/// Takes STRING `pulse` messages (any device; `pulse`, optionally `output=<percent>`, in any
/// case: [`Announced::parse`]) from a client's message channel ([`Client::take_messages`]) and
/// passes them on with their reception times and the sender's timestamp (the stimulator's own
/// time, when it set one), until `stop` (checked at least every 100 ms) or the channel closes.
pub fn forward_pulses(
    rx: &Receiver<mocomp_igtl::client::Received>,
    to: &SyncSender<Announced>,
    stop: &std::sync::atomic::AtomicBool,
) {
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        match rx.recv_timeout(std::time::Duration::from_millis(100)) {
            Ok(r) => {
                let stamp = r.message.timestamp;
                if let Body::String { text, .. } = &r.message.body
                    && let Some(a) = Announced::parse(
                        &String::from_utf8_lossy(text),
                        r.received_s,
                        (!stamp.is_none()).then(|| stamp.to_secs_f64()),
                    )
                    && let Err(TrySendError::Disconnected(_)) = to.try_send(a)
                {
                    return;
                }
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return,
        }
    }
}

/// The session's figures for the run's report.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct SessionReport {
    /// Pulses logged.
    pub pulses: u64,
    /// Of them, while the gate was shut.
    pub pulses_off_target: u64,
    /// The largest position error at a pulse while the gate was open, mm.
    pub pulse_error_max_mm: f64,
    /// The largest dose error at a pulse while the gate was open, |dose − planned| in % of the
    /// planned (NaN: no pulse with a dose).
    pub pulse_dose_error_max_pct: f64,
    /// Times the gate opened.
    pub gate_openings: u64,
    /// The drift monitor's largest filtered offset reported, mm (NaN: no drift monitor or no
    /// warning).
    pub drift_max_mm: f64,
    /// The calibration was called invalid (the loop held).
    pub calibration_invalid: bool,
    /// Why the pulse log stopped being written, if it did.
    pub pulse_log_error: Option<String>,
}

/// Where the gate is published: set once the session's OpenIGTLink client is up.
pub type Publisher = std::sync::Arc<std::sync::OnceLock<std::sync::Arc<Client>>>;

/// The logger thread's side: the pulse log, the gate over OpenIGTLink, the figures.
pub struct SessionLog {
    names: Vec<String>,
    recorder: mocomp_session::Recorder,
    log: Option<mocomp_session::PulseLog<std::fs::File>>,
    /// The client the gate is published on, once connected, and the device.
    publish: Option<(Publisher, String)>,
    /// The figures.
    pub report: SessionReport,
}

impl std::fmt::Debug for SessionLog {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SessionLog")
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

impl SessionLog {
    /// Opens the pulse log (its header written at once) and takes the client to publish on.
    pub fn open(s: &SessionSetup, publish: Publisher) -> Result<Self, AppError> {
        let log = match &s.pulse_log {
            Some(p) => {
                let f = std::fs::File::create(p)
                    .what(|| format!("session.pulse_log {}", p.display()))?;
                Some(
                    mocomp_session::PulseLog::new(f)
                        .what(|| format!("session.pulse_log {}", p.display()))?,
                )
            }
            None => None,
        };
        Ok(Self {
            names: s.targets.iter().map(|t| t.0.clone()).collect(),
            recorder: s.recorder.clone(),
            log,
            publish: s.igtl_device.clone().map(|d| (publish, d)),
            report: SessionReport {
                drift_max_mm: f64::NAN,
                pulse_dose_error_max_pct: f64::NAN,
                ..SessionReport::default()
            },
        })
    }

    /// Ties the loop's clock to UTC: `utc_minus_loop_s` is UTC (Unix seconds) less the loop's
    /// time, taken once when the loop's clock is known; every pulse's UTC time is its loop time
    /// plus it (both clocks run at the same rate for the length of a session).
    pub fn set_utc_offset(&mut self, utc_minus_loop_s: f64) {
        self.recorder.utc_minus_loop_s = Some(utc_minus_loop_s);
    }

    /// Whether the loop's clock is tied to UTC yet.
    pub fn has_utc_offset(&self) -> bool {
        self.recorder.utc_minus_loop_s.is_some()
    }

    fn name(&self, target: Option<usize>) -> &str {
        target
            .and_then(|i| self.names.get(i))
            .map_or("-", String::as_str)
    }

    /// Takes one note; returns the event-log line it makes.
    pub fn take(&mut self, note: &Note) -> String {
        match *note {
            Note::Pulse(p, target) => {
                let r = &mut self.report;
                r.pulses += 1;
                if p.gate == GateState::Open {
                    r.pulse_error_max_mm = r.pulse_error_max_mm.max(p.position_error_m * 1e3);
                    if p.dose.1.is_finite() {
                        // NaN (none yet) gives way to the first.
                        r.pulse_dose_error_max_pct =
                            r.pulse_dose_error_max_pct.max((p.dose.1 - 100.0).abs());
                    }
                } else {
                    r.pulses_off_target += 1;
                }
                let row = self.recorder.row(&p, self.name(target));
                if let Some(log) = self.log.as_mut()
                    && let Err(e) = log.write(&row)
                {
                    self.report.pulse_log_error = Some(e.to_string());
                    self.log = None;
                }
                let gate = match p.gate {
                    GateState::Open => "gate open".to_string(),
                    GateState::Shut(s) => format!("OFF TARGET: {}", shut_reason(&s)),
                };
                let dose = if p.dose.1.is_finite() {
                    format!(", dose {:.1} V/m ({:.1} %)", p.dose.0, p.dose.1)
                } else {
                    String::new()
                };
                format!(
                    "pulse on {}: {:.2} mm, {:.2} deg{dose}, {gate}",
                    self.name(target),
                    p.position_error_m * 1e3,
                    p.angle_error_rad.to_degrees()
                )
            }
            Note::Gate(_, e, target) => {
                let text = match e {
                    GateEvent::Opened => {
                        self.report.gate_openings += 1;
                        "open".to_string()
                    }
                    GateEvent::Shut(s) => format!("shut: {}", shut_reason(&s)),
                };
                if let Some((client, device)) = &self.publish
                    && let Some(client) = client.get()
                    && let Ok(m) = mocomp_igtl::Message::new(
                        "STRING",
                        device,
                        Body::String {
                            encoding: 3,
                            text: text.clone().into_bytes(),
                        },
                    )
                {
                    // Not connected (the server restarting): the next change is sent again.
                    client.send(&m).ok();
                }
                format!("gate {text} on {}", self.name(target))
            }
            Note::Drift(_, d) => {
                let (m, a) = match d {
                    Drift::Ok => (0.0, 0.0),
                    Drift::Warning(m, a) | Drift::Invalid(m, a) => (m, a),
                };
                if m > 0.0 {
                    let mm = m * 1e3;
                    // NaN (none yet) gives way to the first.
                    self.report.drift_max_mm = self.report.drift_max_mm.max(mm);
                }
                match d {
                    Drift::Ok => "calibration drift back within the warning levels".into(),
                    Drift::Warning(..) => format!(
                        "calibration drift warning: the flange marker is {:.2} mm, {:.2} deg from \
                         where the calibration puts it",
                        m * 1e3,
                        a.to_degrees()
                    ),
                    Drift::Invalid(..) => {
                        self.report.calibration_invalid = true;
                        format!(
                            "calibration no longer valid (tracker or base moved): {:.2} mm, {:.2} \
                             deg; the loop holds until recalibrated",
                            m * 1e3,
                            a.to_degrees()
                        )
                    }
                }
            }
            Note::Selected(_, i) => format!("target {} selected", self.name(Some(i))),
            Note::OutputFailed(_) => "the gate output could not be set".into(),
            Note::Camera(_, n) => n.to_string(),
            Note::Rearm(_, r) => r.to_string(),
        }
    }

    /// Flushes the pulse log.
    pub fn finish(&mut self) {
        if let Some(log) = self.log.take()
            && let Err(e) = log.into_inner()
        {
            self.report.pulse_log_error = Some(e.to_string());
        }
    }
}

/// Selects the running session's target `name`: checked with the loop's goal check on the
/// running configuration `config`, then given to the loop (which goes there by a planned path
/// while it keeps compensating). Returns its index. Refused, with why: an unknown name, a goal
/// the check refuses, a loop that has ended or still has an earlier selection waiting.
pub fn select_target(
    config: &crate::config::Config,
    controls: &crate::frontend::Controls,
    name: &str,
) -> Result<usize, AppError> {
    let targets = controls.targets();
    let Some(index) = targets.iter().position(|t| t.0 == name) else {
        refuse!(
            "no target {name:?} in this session (it has: {})",
            targets
                .iter()
                .map(|t| t.0.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        );
    };
    let goal = targets[index].1;
    mocomp_control::check_goal(
        &config.head_model()?,
        &config.coil_model(),
        &goal,
        config.params.goal_min_distance_m(),
    )
    .map_err(|e| AppError::Refused(format!("target {name:?}: {e}")))?;
    controls.select_target(index, goal)?;
    Ok(index)
}

/// Starts free-drive (the arm yields to the operator's hand) while the operator holds the loop,
/// or hands back to the loop (`on` false). Refused while the loop is not held: a coil that
/// follows a head must not go limp under a hand.
pub fn set_freedrive(controls: &crate::frontend::Controls, on: bool) -> Result<(), AppError> {
    if on && !controls.hold() {
        refuse!("hold the loop first: free-drive starts from a coil standing still");
    }
    controls.set_freedrive(on);
    Ok(())
}
