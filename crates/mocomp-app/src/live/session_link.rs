//! The clinical session's wiring around `mocomp run`'s loop ([`crate::live::session`] is what it
//! does): its log opened before the robot connects (a path that cannot be written stops the run
//! before anything moves), then, once the world is up, its own OpenIGTLink connection (the drift
//! marker's poses, the pulses the server announces, the gate published back), the thread that
//! forwards the pulses, and the camera's notes into its log. [`SessionLink::finish`] takes it
//! down in the order it needs.

use crate::config::Setup;
use crate::frontend::{Controls, Note};
use crate::live::session::{LoopSession, Publisher, SessionLog, SessionSetup};
use crate::world::World;
use crate::{AppError, Context};
use mocomp_geom::Clock;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_igtl::client::Client;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, OnceLock};
use std::thread::JoinHandle;

/// Notes the loop's thread may queue before the logger takes them.
const NOTES: usize = 1024;
/// Pulses the forwarding thread may queue before the loop takes them.
const PULSES: usize = 64;

/// The session before the world is connected: its configuration and its log.
#[derive(Debug)]
pub struct SessionStart {
    setup: SessionSetup,
    notes_tx: SyncSender<Note>,
    publisher: Publisher,
}

/// The session's end on the logger's thread: its notes and its log.
#[derive(Debug)]
pub struct SessionLogSide {
    /// The notes the loop's thread sends.
    pub notes: Receiver<Note>,
    /// The pulse log and the figures.
    pub log: SessionLog,
}

/// The session's connections while the loop runs.
#[derive(Debug)]
pub struct SessionLink {
    /// The start target's goal, for the first cycle.
    pub start_goal: Option<Isometry3<f64>>,
    client: Option<Arc<Client>>,
    forwarder: Option<JoinHandle<()>>,
    forwarding_done: Arc<AtomicBool>,
}

impl SessionStart {
    /// Reads `[session]` and opens its log; the log's side goes to the logger's thread.
    pub fn open(setup: &Setup) -> Result<(Self, SessionLogSide), AppError> {
        let session = SessionSetup::from_setup(setup)?;
        let (notes_tx, notes) = sync_channel::<Note>(NOTES);
        let publisher: Publisher = Arc::new(OnceLock::new());
        let log = SessionLog::open(&session, Arc::clone(&publisher))?;
        Ok((
            Self {
                setup: session,
                notes_tx,
                publisher,
            },
            SessionLogSide { notes, log },
        ))
    }

    /// Connects the session to the `world` (on its `clock`): the camera's notes into the log,
    /// the session's OpenIGTLink connection and pulse thread, the targets offered to the front
    /// ends through `controls`. Returns what runs on the loop's thread after each cycle, and
    /// the connections.
    pub fn connect(
        self,
        setup: &Setup,
        world: &World,
        clock: &Arc<dyn Clock>,
        controls: &Controls,
    ) -> Result<(LoopSession, SessionLink), AppError> {
        let s = &self.setup;
        if let Some(c) = &world.camera {
            c.notify(self.notes_tx.clone(), Arc::clone(clock));
        }
        let client = (s.marker.is_some() || s.igtl_device.is_some()).then(|| {
            let device = s
                .marker
                .as_ref()
                .map_or(setup.file.tracker.device.as_str(), |m| m.0.as_str());
            // Pulses over OpenIGTLink only without a pulse input (one source of pulses).
            let keep = if self.by_message() { 256 } else { 0 };
            world.client_keeping(setup, device, keep)
        });
        let (client, messages) = match client {
            Some(c) => {
                let m = c.take_messages();
                (Some(Arc::new(c)), m)
            }
            None => (None, None),
        };
        if let (Some(c), Some(_)) = (&client, &s.igtl_device) {
            self.publisher.set(Arc::clone(c)).ok();
        }
        let (pulses_tx, pulses_rx) = sync_channel::<mocomp_session::Announced>(PULSES);
        let forwarding_done = Arc::new(AtomicBool::new(false));
        let forwarder = match (&client, messages) {
            (Some(_), Some(rx)) if s.params.pulse_input.is_none() => {
                let stop = Arc::clone(&forwarding_done);
                Some(
                    std::thread::Builder::new()
                        .name("mocomp-pulses".into())
                        .spawn(move || {
                            mocomp_rt::leave_realtime().ok();
                            crate::live::session::forward_pulses(&rx, &pulses_tx, &stop);
                        })
                        .what(|| "starting the pulse listener")?,
                )
            }
            _ => None,
        };
        let loop_session = LoopSession::new(
            s,
            setup,
            client
                .as_ref()
                .filter(|_| s.marker.is_some())
                .map(|c| c.pose_source()),
            forwarder.is_some().then_some(pulses_rx),
            self.notes_tx,
        );
        controls.attach_targets(Arc::new(s.targets.clone()));
        let start_goal = s.start.and_then(|i| s.targets.get(i)).map(|t| t.1);
        Ok((
            loop_session,
            SessionLink {
                start_goal,
                client,
                forwarder,
                forwarding_done,
            },
        ))
    }

    /// Whether pulses come as OpenIGTLink messages (no robot input named for them).
    fn by_message(&self) -> bool {
        self.setup.igtl_device.is_some() && self.setup.params.pulse_input.is_none()
    }
}

impl SessionLink {
    /// Stops forwarding pulses (the loop has ended) and waits for the thread. The session's
    /// connection stays up while the logger still publishes through it: drop what this returns
    /// after the logger's end.
    pub fn finish(self) -> Option<Arc<Client>> {
        self.forwarding_done.store(true, Ordering::Relaxed);
        if let Some(f) = self.forwarder {
            f.join().ok();
        }
        self.client
    }
}
