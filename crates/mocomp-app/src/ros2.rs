//! `mocomp run` as a ROS 2 node (`[ros2]`, `--ros2`): the node ([`mocomp_ros2::Ros2Bridge`]) is
//! started before the robot connects; an [`Observer`] on the logger's thread turns each cycle
//! into what the node publishes (never on the loop's thread); the hold and resume services reach
//! the loop through a channel its pace polls, as the console's buttons do.

use crate::config::{Setup, TrackerSource};
use crate::live::{Observer, Status, mode_name};
use crate::{AppError, Context};
use mocomp_control::{CycleRecord, Event, Mode};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::Arm;
use mocomp_ros2::node::Call;
use mocomp_ros2::{Out, Ros2Bridge, Snapshot};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

/// The node and the service calls it took, for the loop's pace.
#[derive(Debug)]
pub struct Ros2Link {
    /// The node.
    pub bridge: Arc<Ros2Bridge>,
    /// Hold and resume calls.
    pub calls: Receiver<Call>,
}

/// Starts the node when `[ros2]` is enabled or the head's poses come over ROS 2 (`None`
/// otherwise). Errors name what DDS refused.
pub fn start(setup: &Setup) -> Result<Option<Ros2Link>, AppError> {
    let file = &setup.file;
    let head = file.tracker.source == TrackerSource::Ros2;
    if !(file.ros2.enabled || head) {
        return Ok(None);
    }
    let cfg = file.ros2.node_config(head)?;
    let (tx, calls) = sync_channel::<Call>(4);
    let handler: Option<mocomp_ros2::node::Handler> = file.ros2.enabled.then(|| {
        let tx: SyncSender<Call> = tx;
        Box::new(move |call: Call| match tx.try_send(call) {
            Ok(()) => Ok(match call {
                Call::Hold => "hold requested".to_string(),
                Call::Resume => "resume requested".to_string(),
            }),
            Err(TrySendError::Full(_)) => Err("earlier calls still wait for the loop".into()),
            Err(TrySendError::Disconnected(_)) => Err("the loop has ended".into()),
        }) as mocomp_ros2::node::Handler
    });
    let bridge =
        Ros2Bridge::start(&cfg, handler).what(|| format!("ros2 (domain {})", cfg.domain_id))?;
    Ok(Some(Ros2Link {
        bridge: Arc::new(bridge),
        calls,
    }))
}

/// Publishes each cycle (at most `ros2.publish_hz`) and the status through the node.
#[derive(Debug)]
pub struct Ros2Observer {
    bridge: Arc<Ros2Bridge>,
    arm: Arm,
    flange_from_coil: Isometry3<f64>,
    base_from_tracker: Isometry3<f64>,
    min_period_s: f64,
    last_t: f64,
}

impl Ros2Observer {
    /// The observer of `setup`'s loop, publishing through `bridge`.
    pub fn new(setup: &Setup, bridge: Arc<Ros2Bridge>) -> Result<Self, AppError> {
        let hz = setup.file.ros2.publish_hz;
        Ok(Self {
            bridge,
            arm: setup.arm,
            flange_from_coil: setup.file.flange_from_coil()?,
            base_from_tracker: setup.base_from_tracker,
            min_period_s: if hz > 0.0 { 1.0 / hz } else { 0.0 },
            last_t: f64::NEG_INFINITY,
        })
    }
}

fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(f64::NAN, |d| d.as_secs_f64())
}

impl Observer for Ros2Observer {
    fn event(&mut self, _t: f64, _event: &Event) {}

    fn status(&mut self, s: &Status) {
        let level = match s.mode {
            Mode::Tracking => 0,
            Mode::Approaching | Mode::Holding(_) | Mode::Retreating(_) => 1,
            Mode::Faulted(_) => 2,
        };
        let f = |x: f64| format!("{x:.3}");
        self.bridge.send(Out::Status(mocomp_ros2::Status {
            stamp_unix_s: unix_now(),
            level,
            message: mode_name(&s.mode),
            values: vec![
                ("rate_hz".into(), format!("{:.0}", s.rate_hz)),
                ("deviation_max_mm".into(), f(s.deviation_max_m * 1e3)),
                ("horizon_ms".into(), f(s.horizon_s * 1e3)),
                ("sample_age_ms".into(), f(s.sample_age_s * 1e3)),
                ("command_delay_ms".into(), f(s.command_delay_s * 1e3)),
            ],
        }));
    }

    fn cycle(&mut self, r: &CycleRecord, age_s: f64) {
        if r.t - self.last_t < self.min_period_s * 0.999
            || !r.q_actual.iter().all(|q| q.is_finite())
        {
            return;
        }
        self.last_t = r.t;
        let age = if age_s.is_finite() {
            age_s.max(0.0)
        } else {
            0.0
        };
        let base_from_flange = self.arm.fk_flange(&r.q_actual);
        self.bridge.send(Out::Cycle(Box::new(Snapshot {
            stamp_unix_s: unix_now() - age,
            q: r.q_actual,
            qd: r.qd_actual,
            base_from_flange,
            base_from_coil: base_from_flange * self.flange_from_coil,
            base_from_tracker: self.base_from_tracker,
            tracker_from_head: r.head_now,
            head_from_coil_goal: r.head_from_coil_goal,
        })));
    }
}
