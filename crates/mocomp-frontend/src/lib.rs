//! The contract between a running loop and its front ends (the CLI's printer, the console,
//! ROS 2, a recording): what they are told ([`Observer`], [`Status`], [`Note`], [`mode_name`])
//! and how they steer the loop ([`Controls`]), with the camera pipeline's link ([`vision`]).
//! The live session and the experiment both speak it.
//!
//! **Limits.** No I/O, no thread, no loop: flags, bounded channels and types. Nothing here
//! reaches into the session, the experiment or a front end, so each depends on this and not on
//! the others.

pub mod vision;

use mocomp_control::{CycleRecord, Event, LoopParams, Mode};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_session::{Drift, GateEvent, PulseAt};
use mocomp_vision::VisionError;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Condvar, Mutex, OnceLock, PoisonError};
use vision::VisionLink;

/// What a front end's request could not do.
#[derive(Debug, thiserror::Error)]
pub enum FrontendError {
    /// The loop cannot take the request (it is busy with earlier ones, or has ended).
    #[error("{0}")]
    Refused(String),
    /// A value out of range; the message names the key.
    #[error("{0}")]
    Config(String),
    /// Making `what` from the camera's frame failed.
    #[error("{what}")]
    Vision {
        /// What was being made.
        what: &'static str,
        /// Why it failed.
        #[source]
        source: VisionError,
    },
}

/// Offers `value` to the loop through `tx` without waiting: refused while `earlier` (what is
/// still queued, as a sentence's subject) waits, or once the loop has ended.
fn offer<T>(tx: &SyncSender<T>, value: T, earlier: &str) -> Result<(), FrontendError> {
    match tx.try_send(value) {
        Ok(()) => Ok(()),
        Err(TrySendError::Full(_)) => Err(FrontendError::Refused(format!(
            "{earlier} still waiting for the loop; try again"
        ))),
        Err(TrySendError::Disconnected(_)) => {
            Err(FrontendError::Refused("the loop has ended".into()))
        }
    }
}

/// The session's targets: name and `head_from_coil`, in the file's order.
pub type NamedTargets = Vec<(String, Isometry3<f64>)>;

/// The loop's status, once a second.
#[derive(Debug, Clone, PartialEq)]
pub struct Status {
    /// Loop time, s.
    pub t: f64,
    /// Cycles per second since the last status.
    pub rate_hz: f64,
    /// The prediction horizon, s: sample age + command delay + lookahead.
    pub horizon_s: f64,
    /// The newest sample's age, s.
    pub sample_age_s: f64,
    /// From the cycle's start to the command, s.
    pub command_delay_s: f64,
    /// The largest deviation while tracking since the last status, m.
    pub deviation_max_m: f64,
    /// The loop's mode.
    pub mode: Mode,
}

/// What a front end is told while the loop runs (called on the logger thread, never on the
/// loop's).
pub trait Observer: Send {
    /// An event at loop time `t`.
    fn event(&mut self, t: f64, event: &Event);
    /// The status, once a second.
    fn status(&mut self, status: &Status);
    /// Every cycle's record (before its event and status, if any), and its age on the loop's
    /// clock when the logger took it, s (the hop from the loop to here; NaN before the clock is
    /// known).
    fn cycle(&mut self, _record: &CycleRecord, _age_s: f64) {}
    /// What the session did at loop time `t` (a pulse, the gate, the drift monitor), in words.
    fn session(&mut self, _t: f64, _text: &str) {}
    /// The same note as it is (before [`Self::session`]'s words): for what counts or shows it
    /// (the console's gate and pulse tiles).
    fn note(&mut self, _note: &Note) {}
    /// The loop has ended: the last call (a recording is closed here).
    fn finish(&mut self) {}
}

/// Tells two observers.
#[derive(Debug)]
pub struct Both<A, B>(pub A, pub B);

impl<A: Observer, B: Observer> Observer for Both<A, B> {
    fn event(&mut self, t: f64, event: &Event) {
        self.0.event(t, event);
        self.1.event(t, event);
    }
    fn status(&mut self, status: &Status) {
        self.0.status(status);
        self.1.status(status);
    }
    fn cycle(&mut self, record: &CycleRecord, age_s: f64) {
        self.0.cycle(record, age_s);
        self.1.cycle(record, age_s);
    }
    fn session(&mut self, t: f64, text: &str) {
        self.0.session(t, text);
        self.1.session(t, text);
    }
    fn note(&mut self, note: &Note) {
        self.0.note(note);
        self.1.note(note);
    }
    fn finish(&mut self) {
        self.0.finish();
        self.1.finish();
    }
}

impl<O: Observer + ?Sized> Observer for Box<O> {
    fn event(&mut self, t: f64, event: &Event) {
        (**self).event(t, event);
    }
    fn status(&mut self, status: &Status) {
        (**self).status(status);
    }
    fn cycle(&mut self, record: &CycleRecord, age_s: f64) {
        (**self).cycle(record, age_s);
    }
    fn session(&mut self, t: f64, text: &str) {
        (**self).session(t, text);
    }
    fn note(&mut self, note: &Note) {
        (**self).note(note);
    }
    fn finish(&mut self) {
        (**self).finish();
    }
}

/// A target selected: its index in the session's targets and its `head_from_coil`.
pub type Selection = (usize, Isometry3<f64>);

/// Parameter changes that may wait for the loop to take them.
const PENDING_PARAMS: usize = 4;

/// What front ends ask of a running loop: stop, the operator's hold, new loop parameters. The
/// loop reads them each cycle without a lock: two flags, and a bounded channel it polls (its
/// receiving end is taken once, when the loop starts).
#[derive(Debug)]
pub struct Controls {
    stop: AtomicBool,
    hold: AtomicBool,
    /// The operator's resumes so far (each one re-arms a latched fault).
    resumes: AtomicU64,
    freedrive: AtomicBool,
    /// The running session's targets, once the loop has started.
    targets: OnceLock<Arc<NamedTargets>>,
    start: AtomicBool,
    params_tx: SyncSender<LoopParams>,
    params_rx: Mutex<Option<Receiver<LoopParams>>>,
    goal_tx: SyncSender<Isometry3<f64>>,
    goal_rx: Mutex<Option<Receiver<Isometry3<f64>>>>,
    target_tx: SyncSender<Selection>,
    target_rx: Mutex<Option<Receiver<Selection>>>,
    /// The simulated camera's pipeline, once the session has started one.
    vision: OnceLock<Arc<VisionLink>>,
    /// Wakes a front end waiting for the operator's go or stop ([`Controls::wait_for_start`]);
    /// the loop never takes it.
    asked: (Mutex<()>, Condvar),
}

impl Controls {
    /// Controls with nothing asked yet.
    pub fn new() -> Arc<Self> {
        let (params_tx, rx) = sync_channel(PENDING_PARAMS);
        let (goal_tx, goal_rx) = sync_channel(1);
        let (target_tx, target_rx) = sync_channel(1);
        Arc::new(Self {
            stop: AtomicBool::new(false),
            hold: AtomicBool::new(false),
            resumes: AtomicU64::new(0),
            freedrive: AtomicBool::new(false),
            targets: OnceLock::new(),
            start: AtomicBool::new(false),
            params_tx,
            params_rx: Mutex::new(Some(rx)),
            goal_tx,
            goal_rx: Mutex::new(Some(goal_rx)),
            target_tx,
            target_rx: Mutex::new(Some(target_rx)),
            vision: OnceLock::new(),
            asked: (Mutex::new(()), Condvar::new()),
        })
    }

    /// The running session's targets, once (the loop's start sets them).
    pub fn attach_targets(&self, targets: Arc<NamedTargets>) {
        self.targets.set(targets).ok();
    }

    /// The session's camera pipeline, once (the loop's start sets it).
    pub fn attach_vision(&self, vision: Arc<VisionLink>) {
        self.vision.set(vision).ok();
    }

    /// The session's camera pipeline (its parameters, its newest frame), when it has one.
    pub fn vision(&self) -> Option<&Arc<VisionLink>> {
        self.vision.get()
    }

    /// Ends the loop at its next cycle; the robot is then stopped.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::Relaxed);
        self.wake();
    }

    /// Whether the stop was asked.
    pub fn stop_requested(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// The operator's go for a procedure that waits for one before the arm moves (the
    /// calibration collection with a console).
    pub fn request_start(&self) {
        self.start.store(true, Ordering::Relaxed);
        self.wake();
    }

    /// Waits until the operator gives the go (`true`) or asks to stop (`false`), for a front end
    /// with nothing else to do meanwhile (a procedure that must keep a robot's program fed
    /// polls [`Self::start_requested`] instead).
    pub fn wait_for_start(&self) -> bool {
        let (lock, asked) = &self.asked;
        let guard = lock.lock().unwrap_or_else(PoisonError::into_inner);
        let _guard = asked
            .wait_while(guard, |_| !self.start_requested() && !self.stop_requested())
            .unwrap_or_else(PoisonError::into_inner);
        !self.stop_requested()
    }

    /// Tells a waiter a flag changed. Taking the lock after the flag is set means a waiter
    /// that checked the flags before is already waiting when it is woken.
    fn wake(&self) {
        let (lock, asked) = &self.asked;
        drop(lock.lock().unwrap_or_else(PoisonError::into_inner));
        asked.notify_all();
    }

    /// Whether the operator gave the go.
    pub fn start_requested(&self) -> bool {
        self.start.load(Ordering::Relaxed)
    }

    /// The operator's hold (`true`) or resume.
    pub fn set_hold(&self, hold: bool) {
        self.hold.store(hold, Ordering::Relaxed);
    }

    /// The operator's resume: ends their hold, and re-arms a fault that latched (the controller
    /// had stopped the arm): the robot's recovery (reconnect, program restart, a protective stop
    /// unlocked) is done before the next cycle, and the loop comes back from where the arm is,
    /// by a path. Nothing else ever re-arms the loop.
    pub fn resume(&self) {
        self.hold.store(false, Ordering::Relaxed);
        self.resumes.fetch_add(1, Ordering::Relaxed);
    }

    /// How many resumes the operator has asked for.
    pub fn resumes(&self) -> u64 {
        self.resumes.load(Ordering::Relaxed)
    }

    /// Whether the operator holds the loop.
    pub fn hold(&self) -> bool {
        self.hold.load(Ordering::Relaxed)
    }

    /// Free-drive (`true`: the arm yields to the operator's hand while the loop keeps it
    /// alive) or the hand-over back to the loop (`false`).
    pub fn set_freedrive(&self, on: bool) {
        self.freedrive.store(on, Ordering::Relaxed);
    }

    /// Whether free-drive is asked for.
    pub fn freedrive(&self) -> bool {
        self.freedrive.load(Ordering::Relaxed)
    }

    /// The running session's targets (name, `head_from_coil`) in the order
    /// [`Self::select_target`] numbers them; empty before the loop starts or without targets.
    pub fn targets(&self) -> &[(String, Isometry3<f64>)] {
        self.targets.get().map_or(&[], |t| t.as_slice())
    }

    /// New loop parameters (already validated) for the loop to take at its next cycle.
    pub fn tune(&self, params: LoopParams) -> Result<(), FrontendError> {
        offer(&self.params_tx, params, "earlier parameter changes are")
    }

    /// A new goal (`head_from_coil`, checked with the loop's goal check) for the loop to take at
    /// its next cycle.
    pub fn set_goal(&self, head_from_coil: Isometry3<f64>) -> Result<(), FrontendError> {
        offer(&self.goal_tx, head_from_coil, "an earlier goal is")
    }

    /// Selects the session's target `index` (its `head_from_coil`, checked with the loop's goal
    /// check): the loop goes there by a planned path while it keeps compensating, and the gate
    /// stays shut until it is on it.
    pub fn select_target(
        &self,
        index: usize,
        head_from_coil: Isometry3<f64>,
    ) -> Result<(), FrontendError> {
        offer(
            &self.target_tx,
            (index, head_from_coil),
            "an earlier target is",
        )
    }

    /// The loop's end of the target channel (once).
    pub fn take_targets(&self) -> Option<Receiver<Selection>> {
        self.target_rx
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
    }

    /// The loop's end of the goal channel (once).
    pub fn take_goals(&self) -> Option<Receiver<Isometry3<f64>>> {
        self.goal_rx
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
    }

    /// The loop's end of the parameter channel (once).
    pub fn take_params(&self) -> Option<Receiver<LoopParams>> {
        self.params_rx
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .take()
    }
}

/// An observer that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Observer for Silent {
    fn event(&mut self, _: f64, _: &Event) {}
    fn status(&mut self, _: &Status) {}
}

/// The mode as the log and the report name it.
pub fn mode_name(m: &Mode) -> String {
    match m {
        Mode::Tracking => "tracking".into(),
        Mode::Approaching => "approaching".into(),
        Mode::Holding(r) => format!("holding ({r:?})"),
        Mode::Faulted(r) => format!("faulted ({r:?})"),
        Mode::Retreating(r) => format!("retreating ({r:?})"),
    }
}

/// What the session tells the logger thread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Note {
    /// The gate opened or shut at loop time `.0`, on target `.2`.
    Gate(f64, GateEvent, Option<usize>),
    /// A pulse, on target `.1` (`None`: the configuration's goal).
    Pulse(PulseAt, Option<usize>),
    /// The drift monitor's verdict changed at loop time `.0`.
    Drift(f64, Drift),
    /// The operator selected target `.1` at loop time `.0`.
    Selected(f64, usize),
    /// The gate output could not be set (the robot refused the write).
    OutputFailed(f64),
    /// The depth camera's news at loop time `.0`: frames dropped, its end.
    Camera(f64, vision::CameraNote),
    /// The operator's re-arm at loop time `.0`: what the robot's recovery did, or why it could
    /// not.
    Rearm(f64, RearmOutcome),
}

/// What a re-arm came to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RearmOutcome {
    /// The robot is back (the loop comes back from where the arm is, by a path).
    Done(mocomp_ur::recovery::Recovered),
    /// Software may not do what is needed: the operator acts at the cell, then resumes again.
    Refused(mocomp_ur::recovery::Refusal),
    /// A recovery step failed: the controller did not answer as expected.
    Failed(mocomp_ur::recovery::Step),
}

impl std::fmt::Display for RearmOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Done(r) => write!(f, "re-armed: {r}"),
            Self::Refused(r) => write!(f, "re-arm refused: {r}"),
            Self::Failed(step) => write!(
                f,
                "re-arm failed ({step:?}): the controller did not answer as expected; the arm \
                 stays stopped; check the controller, then resume again"
            ),
        }
    }
}

/// The time of a note on the loop's clock.
pub fn note_time(n: &Note) -> f64 {
    match *n {
        Note::Gate(t, ..)
        | Note::Drift(t, _)
        | Note::Selected(t, _)
        | Note::OutputFailed(t)
        | Note::Camera(t, _)
        | Note::Rearm(t, _) => t,
        Note::Pulse(p, _) => p.t_s,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_waiting_front_end_wakes_to_the_go_or_the_stop_whichever_comes() {
        // Asked before anyone waits: no wait at all.
        let c = Controls::new();
        c.request_start();
        assert!(c.wait_for_start());

        // Asked by another thread while one waits (the thread may run before or after the wait
        // begins: either way the waiter sees it).
        for go in [true, false] {
            let c = Controls::new();
            let asker = {
                let c = Arc::clone(&c);
                std::thread::spawn(move || if go { c.request_start() } else { c.stop() })
            };
            assert_eq!(c.wait_for_start(), go);
            asker.join().unwrap();
        }

        // A stop wins over a go given too: the operator asked to end it.
        let c = Controls::new();
        c.request_start();
        c.stop();
        assert!(!c.wait_for_start());
    }
}
