//! `mocomp demo --record FILE.mcap`: the experiment's runs recorded as `mocomp run --record`
//! records a live session (the same topics, the same CDR messages and schemas), one run after
//! the other on the experiment's stepped clock, each cycle record naming its controller. The
//! experiment's thread hands each cycle to a writer thread (blocking when the writer falls
//! behind: the stepped clock waits, and no cycle is lost); the writer builds the messages, the
//! once-a-second status and the file.
//!
//! Stamps: the wall time the recording started plus the stepped clock's time, so the runs keep
//! their spacing and order, and the recording reads as a session of that day.

use crate::experiment::Controller;
use crate::frontend::{Observer, Status};
use crate::live::logger::RecordOutcome;
use crate::live::ros2::{Rig, cycle_record_msg, diagnostic, unix_ns};
use crate::{AppError, Context};
use mocomp_control::{CycleRecord, Event, LoopConfig, Mode};
use mocomp_kin::Arm;
use mocomp_record::Recorder;
use std::io::BufWriter;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

/// Cycles the writer may fall behind by before the experiment waits for it.
const QUEUE: usize = 4096;

/// What the experiment's thread hands the writer.
// Nearly every item is a cycle: boxing it would allocate once per cycle.
#[allow(clippy::large_enum_variant)]
enum Item {
    /// A controller's run starts.
    Run(&'static str, Box<Rig>),
    /// One of its cycles.
    Cycle(CycleRecord),
    /// The run has ended.
    End,
}

/// A recording of the demo, open while the experiment runs.
#[derive(Debug)]
pub struct DemoRecording {
    tx: SyncSender<Item>,
    writer: JoinHandle<RecordOutcome>,
}

impl std::fmt::Debug for Item {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Item::Run(..) => "Run",
            Item::Cycle(_) => "Cycle",
            Item::End => "End",
        })
    }
}

impl DemoRecording {
    /// Creates `path` (replacing a file there) and starts the writer; `frames` and `node_name`
    /// as `[ros2]` names them.
    pub fn create(
        path: &str,
        frames: mocomp_ros2::Frames,
        node_name: String,
    ) -> Result<Self, AppError> {
        let recorder =
            Recorder::create(std::path::Path::new(path)).what(|| format!("--record {path}"))?;
        let epoch_unix_s = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        let (tx, rx) = sync_channel(QUEUE);
        let mut w = Writer {
            recorder: Some(recorder),
            error: None,
            joint_names: mocomp_ros2::node::UR_JOINTS.map(String::from),
            frames,
            node_name,
            epoch_unix_s,
            run: None,
            window: Window::default(),
        };
        let path = path.to_string();
        let writer = std::thread::Builder::new()
            .name("mocomp-demo-record".into())
            .spawn(move || w.write(rx, path))
            .what(|| "starting the recording's writer".to_string())?;
        Ok(Self { tx, writer })
    }

    /// The observer of `controller`'s run (`arm` carrying the coil, placed by the calibrated
    /// `loop_cfg`, whose `flange_from_coil` is the coil's marker in the experiment).
    pub fn observer(&self, controller: Controller, arm: Arm, loop_cfg: &LoopConfig) -> RunRecorder {
        let rig = Rig {
            arm,
            flange_from_coil: loop_cfg.flange_from_coil,
            base_from_tracker: loop_cfg.base_from_tracker,
        };
        // A writer that has stopped has its error kept for `finish`; the run goes on.
        self.tx
            .send(Item::Run(controller.name(), Box::new(rig)))
            .ok();
        RunRecorder {
            tx: self.tx.clone(),
        }
    }

    /// Closes the file once every run's cycles are written: what it holds, or why it failed.
    pub fn finish(self) -> RecordOutcome {
        let Self { tx, writer } = self;
        drop(tx);
        writer.join().unwrap_or_else(|_| RecordOutcome {
            error: Some("the recording's writer panicked".into()),
            ..RecordOutcome::default()
        })
    }
}

/// One run's observer: hands each cycle to the writer.
#[derive(Debug)]
pub struct RunRecorder {
    tx: SyncSender<Item>,
}

impl Observer for RunRecorder {
    fn event(&mut self, _t: f64, _event: &Event) {}
    fn status(&mut self, _status: &Status) {}
    fn cycle(&mut self, record: &CycleRecord, _age_s: f64) {
        self.tx.send(Item::Cycle(*record)).ok();
    }
    fn finish(&mut self) {
        self.tx.send(Item::End).ok();
    }
}

/// The cycles since the last status, on the stepped clock.
#[derive(Debug, Default)]
struct Window {
    start_t: Option<f64>,
    cycles: u64,
    deviation_max_m: f64,
}

/// The writer thread's state.
struct Writer {
    recorder: Option<Recorder<BufWriter<std::fs::File>>>,
    error: Option<String>,
    joint_names: [String; 6],
    frames: mocomp_ros2::Frames,
    node_name: String,
    epoch_unix_s: f64,
    run: Option<(&'static str, Rig)>,
    window: Window,
}

impl Writer {
    fn write(&mut self, rx: Receiver<Item>, path: String) -> RecordOutcome {
        // Every item is taken, also after a write failed, so the experiment never waits on a
        // writer that has stopped.
        for item in rx {
            match item {
                Item::Run(controller, rig) => {
                    self.run = Some((controller, *rig));
                    self.window = Window::default();
                }
                Item::Cycle(r) => self.cycle(&r),
                Item::End => {
                    self.run = None;
                    self.window = Window::default();
                }
            }
        }
        let messages = self.recorder.as_ref().map_or(0, Recorder::messages);
        let mut error = self.error.take();
        if let Some(r) = self.recorder.take()
            && let Err(e) = r.finish()
        {
            error = Some(e.to_string());
        }
        RecordOutcome {
            path,
            messages,
            error,
        }
    }

    fn put(
        &mut self,
        f: impl FnOnce(
            &mut Recorder<BufWriter<std::fs::File>>,
        ) -> Result<(), mocomp_record::RecordError>,
    ) {
        if let Some(r) = self.recorder.as_mut()
            && let Err(e) = f(r)
        {
            self.error = Some(e.to_string());
            self.recorder = None;
        }
    }

    fn cycle(&mut self, r: &CycleRecord) {
        let Some((controller, rig)) = self.run else {
            return;
        };
        let stamp = self.epoch_unix_s + r.t;
        let t_ns = unix_ns(stamp);
        let record = cycle_record_msg(r, controller);
        let messages = rig
            .snapshot(r, stamp)
            .map(|s| mocomp_ros2::CycleMessages::of(&s, &self.joint_names, &self.frames));
        self.put(|w| w.cycle(t_ns, messages.as_ref(), &record));
        // The status once a second of the run, as the live logger tells it.
        let w = &mut self.window;
        let Some(start) = w.start_t else {
            w.start_t = Some(r.t);
            return;
        };
        w.cycles += 1;
        if r.mode == Mode::Tracking {
            w.deviation_max_m = w.deviation_max_m.max(r.deviation.0);
        }
        if r.t - start >= 1.0 {
            let status = Status {
                t: r.t,
                rate_hz: w.cycles as f64 / (r.t - start),
                horizon_s: r.horizon_s,
                sample_age_s: r.sample_age_s,
                command_delay_s: r.command_delay_s,
                deviation_max_m: w.deviation_max_m,
                mode: r.mode,
            };
            *w = Window {
                start_t: Some(r.t),
                ..Window::default()
            };
            let d = diagnostic(&status, stamp, controller).message(&self.node_name);
            self.put(|w| w.status(t_ns, &d));
        }
    }
}
