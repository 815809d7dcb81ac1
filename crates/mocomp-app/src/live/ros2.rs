//! `mocomp run` as a ROS 2 node (`[ros2]`, `--ros2`) and its MCAP recording (`record_mcap`,
//! `--record`): the node ([`mocomp_ros2::Ros2Bridge`]) is started before the robot connects; an
//! [`Observer`] on the logger's thread turns each cycle into what the node publishes and the
//! recording stores (never on the loop's thread); the hold and resume services call the
//! operator's [`Controls`], as the console's buttons do. The command line attaches it
//! ([`Ros2FrontEnd`]); the live loop knows nothing of ROS 2.

use crate::config::{Setup, TrackerSource};
use crate::frontend::{Controls, Observer, Status, mode_name};
use crate::live::HeadSource;
use crate::live::logger::{RecordOutcome, Ros2Figures, RunReport};
use crate::{AppError, Context};
use mocomp_control::{CycleRecord, Event, Mode};
use mocomp_geom::PoseSource;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::Arm;
use mocomp_ros2::node::Call;
use mocomp_ros2::{Out, Ros2Bridge, Snapshot};
use std::sync::{Arc, PoisonError};

/// ROS 2 and the MCAP recording, attached to `mocomp run` from outside as the console is: an
/// observer for the logger's thread, the node's hold and resume services on the operator's
/// [`Controls`], and, with `tracker.source = "ros2"`, the head's poses from the node's topic.
#[derive(Debug)]
pub struct Ros2FrontEnd {
    bridge: Option<Arc<Ros2Bridge>>,
    observer: Option<RosObserver>,
    record: Option<RecordSlot>,
    head: bool,
}

impl Ros2FrontEnd {
    /// Starts the node when `[ros2]` is enabled or the head's poses come over ROS 2, and the
    /// recording when `record_mcap` is set (`None`: neither). Before the robot connects: a DDS
    /// participant takes a moment. Errors name what DDS refused.
    pub fn start(setup: &Setup, controls: &Arc<Controls>) -> Result<Option<Self>, AppError> {
        let file = &setup.file;
        let head = file.tracker.source == TrackerSource::Ros2;
        let bridge = if file.ros2.enabled || head {
            Some(Arc::new(start_node(setup, head, controls)?))
        } else {
            None
        };
        if bridge.is_none() && file.record_mcap.is_none() {
            return Ok(None);
        }
        let (observer, record) = RosObserver::new(setup, bridge.clone())?;
        Ok(Some(Self {
            bridge,
            observer: Some(observer),
            record,
            head,
        }))
    }

    /// The observer for the logger's thread (once: later calls give `None`).
    pub fn observer(&mut self) -> Option<Box<dyn Observer>> {
        self.observer
            .take()
            .map(|o| Box::new(o) as Box<dyn Observer>)
    }

    /// With `tracker.source = "ros2"`: the head's poses from the node's topic, on the loop's
    /// clock.
    pub fn head_source(&self) -> Option<HeadSource> {
        let bridge = Arc::clone(self.bridge.as_ref().filter(|_| self.head)?);
        Some(Box::new(move |clock| {
            Box::new(bridge.head_source(clock)) as Box<dyn PoseSource>
        }))
    }

    /// What the node published and the recording wrote, into the run's report.
    pub fn finish(self, report: &mut RunReport) {
        report.record = self
            .record
            .and_then(|s| s.lock().unwrap_or_else(PoisonError::into_inner).take());
        report.ros2 = self.bridge.map(|b| {
            let (failures, last_failure) = b.failures();
            Ros2Figures {
                published: b.published(),
                dropped: b.dropped(),
                failures,
                last_failure,
            }
        });
    }
}

/// The node, its hold and resume services calling the operator's `controls` (with `[ros2]`
/// enabled; a node started only for the head's poses offers none).
fn start_node(setup: &Setup, head: bool, controls: &Arc<Controls>) -> Result<Ros2Bridge, AppError> {
    let file = &setup.file;
    let cfg = file.ros2.node_config(head)?;
    let handler: Option<mocomp_ros2::node::Handler> = file.ros2.enabled.then(|| {
        let controls = Arc::clone(controls);
        Box::new(move |call: Call| {
            Ok(match call {
                Call::Hold => {
                    controls.set_hold(true);
                    "hold requested".to_string()
                }
                Call::Resume => {
                    controls.resume();
                    "resume requested".to_string()
                }
            })
        }) as mocomp_ros2::node::Handler
    });
    Ros2Bridge::start(&cfg, handler).what(|| format!("ros2 (domain {})", cfg.domain_id))
}

/// Where the observer leaves the recording's outcome for the run's report.
pub type RecordSlot = Arc<std::sync::Mutex<Option<RecordOutcome>>>;

/// What places a cycle's robot in the world: the arm, the coil on its flange and the
/// calibration (a cycle's record carries the joints and the head; the rest is the setup's).
#[derive(Debug, Clone, Copy)]
pub struct Rig {
    /// The arm's kinematics.
    pub arm: Arm,
    /// The coil on the flange.
    pub flange_from_coil: Isometry3<f64>,
    /// The calibration's tracker in the base.
    pub base_from_tracker: Isometry3<f64>,
}

impl Rig {
    /// The cycle `r` as the node publishes it, stamped `stamp_unix_s` (`None` before the arm's
    /// state was measured).
    pub fn snapshot(&self, r: &CycleRecord, stamp_unix_s: f64) -> Option<Snapshot> {
        if !r.q_actual.iter().all(|q| q.is_finite()) {
            return None;
        }
        let base_from_flange = self.arm.fk_flange(&r.q_actual);
        Some(Snapshot {
            stamp_unix_s,
            q: r.q_actual,
            qd: r.qd_actual,
            base_from_flange,
            base_from_coil: base_from_flange * self.flange_from_coil,
            base_from_tracker: self.base_from_tracker,
            tracker_from_head: r.head_now,
            head_from_coil_goal: r.head_from_coil_goal,
        })
    }
}

/// The cycle record `r` of `controller`'s loop as the recording stores it.
pub fn cycle_record_msg(r: &CycleRecord, controller: &str) -> mocomp_record::CycleRecordMsg {
    mocomp_record::CycleRecordMsg {
        t_s: r.t,
        controller: controller.to_string(),
        mode: mode_name(&r.mode),
        event: r.event.map(|e| format!("{e:?}")).unwrap_or_default(),
        sample_age_s: r.sample_age_s,
        horizon_s: r.horizon_s,
        command_delay_s: r.command_delay_s,
        head_speed_m_s: r.head_speed.0,
        head_speed_rad_s: r.head_speed.1,
        deviation_m: r.deviation.0,
        deviation_rad: r.deviation.1,
        coil_error_m: r.coil_error.0,
        q_command: r.q_command,
        q_actual: r.q_actual,
        contact_force_n: r.contact_force_n,
        compute_ns: r.compute_ns,
        dose_v_per_m: r.dose_v_per_m,
        dose_pct: r.dose_pct,
    }
}

/// The loop's status as `/diagnostics` says it: OK while tracking, WARN while approaching,
/// held or retreating, ERROR when faulted; the figures in ms and mm.
pub fn diagnostic(s: &Status, stamp_unix_s: f64, controller: &str) -> mocomp_ros2::Status {
    let level = match s.mode {
        Mode::Tracking => 0,
        Mode::Approaching | Mode::Holding(_) | Mode::Retreating(_) => 1,
        Mode::Faulted(_) => 2,
    };
    let f = |x: f64| format!("{x:.3}");
    mocomp_ros2::Status {
        stamp_unix_s,
        level,
        message: mode_name(&s.mode),
        values: vec![
            ("controller".into(), controller.to_string()),
            ("rate_hz".into(), format!("{:.0}", s.rate_hz)),
            ("deviation_max_mm".into(), f(s.deviation_max_m * 1e3)),
            ("horizon_ms".into(), f(s.horizon_s * 1e3)),
            ("sample_age_ms".into(), f(s.sample_age_s * 1e3)),
            ("command_delay_ms".into(), f(s.command_delay_s * 1e3)),
        ],
    }
}

/// ns since the Unix epoch (0 for a time that is not one).
pub fn unix_ns(s: f64) -> u64 {
    if s.is_finite() && s > 0.0 {
        (s * 1e9) as u64
    } else {
        0
    }
}

/// On the logger's thread: each cycle to the ROS 2 node (at most `ros2.publish_hz`) and to the
/// recording (every cycle), the status to both.
pub struct RosObserver {
    bridge: Option<Arc<Ros2Bridge>>,
    recorder: Option<mocomp_record::Recorder<std::io::BufWriter<std::fs::File>>>,
    record: Option<(RecordSlot, String)>,
    record_error: Option<String>,
    rig: Rig,
    joint_names: [String; 6],
    frames: mocomp_ros2::Frames,
    node_name: String,
    min_period_s: f64,
    last_t: f64,
}

impl std::fmt::Debug for RosObserver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RosObserver")
            .field("recording", &self.recorder.is_some())
            .finish_non_exhaustive()
    }
}

/// The live loop's controller, as the records and the diagnostics name it.
const LIVE_CONTROLLER: &str = "mocomp";

impl RosObserver {
    /// The observer of `setup`'s loop: publishing through `bridge`, recording to
    /// `record_mcap` (the file is created now; its outcome goes to the slot returned).
    pub fn new(
        setup: &Setup,
        bridge: Option<Arc<Ros2Bridge>>,
    ) -> Result<(Self, Option<RecordSlot>), AppError> {
        let file = &setup.file;
        let hz = file.ros2.publish_hz;
        let (recorder, record) = match &file.record_mcap {
            Some(p) => {
                let path = std::path::Path::new(p);
                let r = mocomp_record::Recorder::create(path)
                    .what(|| format!("record_mcap {}", path.display()))?;
                let slot: RecordSlot = Arc::default();
                (Some(r), Some((slot, p.clone())))
            }
            None => (None, None),
        };
        let slot = record.as_ref().map(|(s, _)| Arc::clone(s));
        Ok((
            Self {
                bridge,
                recorder,
                record,
                record_error: None,
                rig: Rig {
                    arm: setup.arm,
                    flange_from_coil: file.flange_from_coil()?,
                    base_from_tracker: setup.base_from_tracker,
                },
                joint_names: mocomp_ros2::node::UR_JOINTS.map(String::from),
                frames: file.ros2.frames.clone(),
                node_name: file.ros2.node_name.clone(),
                min_period_s: if hz > 0.0 { 1.0 / hz } else { 0.0 },
                last_t: f64::NEG_INFINITY,
            },
            slot,
        ))
    }

    fn recording(
        &mut self,
        f: impl FnOnce(
            &mut mocomp_record::Recorder<std::io::BufWriter<std::fs::File>>,
        ) -> Result<(), mocomp_record::RecordError>,
    ) {
        if let Some(r) = self.recorder.as_mut()
            && let Err(e) = f(r)
        {
            // A recording that cannot be written stops; the run reports it and fails.
            self.record_error = Some(e.to_string());
            self.recorder = None;
        }
    }
}

fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(f64::NAN, |d| d.as_secs_f64())
}

impl Observer for RosObserver {
    fn event(&mut self, _t: f64, _event: &Event) {}

    fn status(&mut self, s: &Status) {
        let status = diagnostic(s, unix_now(), LIVE_CONTROLLER);
        let node_name = self.node_name.clone();
        let t_ns = unix_ns(status.stamp_unix_s);
        self.recording(|r| r.status(t_ns, &status.message(&node_name)));
        if let Some(b) = &self.bridge {
            b.send(Out::Status(status));
        }
    }

    fn cycle(&mut self, r: &CycleRecord, age_s: f64) {
        let age = if age_s.is_finite() {
            age_s.max(0.0)
        } else {
            0.0
        };
        let Some(snapshot) = self.rig.snapshot(r, unix_now() - age) else {
            return;
        };
        if self.recorder.is_some() {
            let messages =
                mocomp_ros2::CycleMessages::of(&snapshot, &self.joint_names, &self.frames);
            let record = cycle_record_msg(r, LIVE_CONTROLLER);
            let t_ns = unix_ns(snapshot.stamp_unix_s);
            self.recording(|w| w.cycle(t_ns, Some(&messages), &record));
        }
        if let Some(b) = &self.bridge
            && r.t - self.last_t >= self.min_period_s * 0.999
        {
            self.last_t = r.t;
            b.send(Out::Cycle(Box::new(snapshot)));
        }
    }

    fn finish(&mut self) {
        let Some((slot, path)) = &self.record else {
            return;
        };
        let mut outcome = RecordOutcome {
            path: path.clone(),
            messages: self.recorder.as_ref().map_or(0, |r| r.messages()),
            error: self.record_error.take(),
        };
        if let Some(r) = self.recorder.take()
            && let Err(e) = r.finish()
        {
            outcome.error = Some(e.to_string());
        }
        *slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(outcome);
    }
}
