//! The OpenIGTLink client: a thread that connects (and reconnects with backoff), reads and
//! decodes the stream, counts everything, maps message timestamps onto our monotonic clock, and
//! publishes the newest pose of one device for the control loop.
//!
//! Timestamps: a message's timestamp is the sender's wall clock at acquisition. How it maps onto
//! our monotonic clock is [`TimestampMode`]:
//! - `Estimated` (default, for a sender whose clock is not synchronised with ours): the offset is
//!   the smallest `receive time − message time` seen (network delay only adds), adapting slowly
//!   upwards for clock drift and reset on every reconnect. That minimum also absorbs the sender's
//!   constant latency (acquisition to sending), which no receiver can observe; give it as
//!   [`ClientConfig::fixed_latency_s`] and it is subtracted. A step in the sender's clock is
//!   re-based and counted (see [`crate::offset`]).
//! - `Synchronized` (a sender on this host, or clocks kept together by PTP/NTP): the message time
//!   is taken at its word, mapped through our own wall clock, so the whole latency is seen.
//! - `Known(offset)`: a simulator stamping with the receiver's own (stepped) clock.
//!
//! Every way, the acquisition time on our clock is never later than the receive time. A timestamp
//! of 0 (unused), or one going backwards for its device, is counted and replaced by the receive
//! time.

use crate::codec::{DEFAULT_MAX_BODY, Decoder, encode};
use crate::message::{Body, Message, pose_of};
use crate::name::{DeviceName, Name};
use crate::offset::OffsetEstimator;
use crate::timestamp::Timestamp;
use mocomp_geom::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use mocomp_geom::{Clock, PoseSample, PoseSource};
use mocomp_geom::{LatestCell, Watch};
use std::collections::HashMap;
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub use mocomp_geom::MonotonicClock;

/// Client settings.
#[derive(Debug, Clone)]
pub struct ClientConfig {
    /// Server address, `host:port` (PLUS and Slicer default to port 18944).
    pub addr: String,
    /// The device whose pose the [`IgtlPoseSource`] publishes (a TRANSFORM or POSITION device
    /// name, or a tool name inside TDATA), e.g. PLUS's `HeadToTracker`.
    pub device: Option<String>,
    /// Send STT_TDATA with this resolution (ms) after connecting.
    pub start_tdata: Option<u32>,
    /// First reconnect delay; doubles up to `reconnect_max`.
    pub reconnect_initial: Duration,
    /// Longest reconnect delay.
    pub reconnect_max: Duration,
    /// Largest body accepted (larger: the connection is dropped).
    pub max_body: u64,
    /// Keep every decoded message in a channel of this capacity (0: none); when the consumer
    /// falls behind, the overflow is counted.
    pub keep_messages: usize,
    /// How message timestamps map onto our clock.
    pub timestamps: TimestampMode,
    /// The sender's constant latency from acquisition to sending, s, which `Estimated` cannot see
    /// (ignored with `Synchronized`, which sees it).
    pub fixed_latency_s: f64,
}

/// How a message's timestamp (the sender's wall clock) maps onto our monotonic clock.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum TimestampMode {
    /// The clocks are unrelated: estimate the offset from the smallest observed delay.
    #[default]
    Estimated,
    /// The sender's wall clock is ours (same host, or synchronised): trust it.
    Synchronized,
    /// The sender's clock plus this offset (s) is our clock: a simulator stamping with the
    /// receiver's own (for instance stepped) clock.
    Known(f64),
}

impl ClientConfig {
    /// Defaults for a server at `addr`: reconnect after 50 ms, backing off to 2 s.
    pub fn new(addr: &str) -> Self {
        Self {
            addr: addr.to_string(),
            device: None,
            start_tdata: None,
            reconnect_initial: Duration::from_millis(50),
            reconnect_max: Duration::from_secs(2),
            max_body: DEFAULT_MAX_BODY,
            keep_messages: 0,
            timestamps: TimestampMode::Estimated,
            fixed_latency_s: 0.0,
        }
    }
}

macro_rules! counters {
    ($($name:ident: $doc:literal),* $(,)?) => {
        /// Everything the client counts (so nothing is lost silently).
        #[derive(Debug, Default)]
        struct Counters { $($name: AtomicU64,)* }
        /// A snapshot of the client's counters.
        #[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
        pub struct ClientCounters { $(#[doc = $doc] pub $name: u64,)* }
        impl Counters {
            fn snapshot(&self) -> ClientCounters {
                ClientCounters { $($name: self.$name.load(Ordering::Acquire),)* }
            }
        }
    };
}

counters! {
    connections: "Connections made.",
    connect_failures: "Connection attempts that failed.",
    disconnects: "Connections lost (closed by the peer or failed).",
    bytes: "Bytes received.",
    messages: "Messages decoded.",
    transforms: "TRANSFORM messages.",
    positions: "POSITION messages.",
    tdata: "TDATA messages.",
    statuses: "STATUS messages.",
    strings: "STRING messages.",
    queries: "GET_/STT_/STP_/RTS_ messages.",
    unknown: "Messages of other types (skipped).",
    crc_errors: "Messages dropped for a CRC mismatch.",
    malformed: "Messages dropped for a bad layout.",
    fatal_errors: "Streams dropped for a bad header (garbage, out of step, body too large).",
    truncated: "Connections lost in the middle of a message.",
    zero_timestamps: "Messages with timestamp 0 (receive time used).",
    backwards_timestamps: "Messages whose timestamp went backwards for their device (receive time used).",
    clock_steps: "Steps of the sender's clock the offset was re-based for (estimated timestamps).",
    poses: "Poses published for the configured device.",
    invalid_poses: "Of those, marked invalid (status metadata, or not rigid).",
    non_rigid: "Transforms of the configured device that were not rigid.",
    consumer_drops: "Messages not kept because the message channel was full.",
    reader_failures: "Times the reader failed (a panic on a message): it dropped the connection and reconnected.",
}

struct Shared {
    counters: Counters,
    latest: LatestCell,
    connected: AtomicBool,
    stop: AtomicBool,
    stream: Mutex<Option<TcpStream>>,
    last_error: Mutex<Option<String>>,
    watch: Watch,
}

/// A message as received.
#[derive(Debug, Clone, PartialEq)]
pub struct Received {
    /// The message.
    pub message: Message,
    /// When it was received, on our clock (seconds).
    pub received_s: f64,
    /// When it was acquired, on our clock (seconds; see the module docs).
    pub acquired_s: f64,
}

/// The running client. Dropping it stops the thread.
pub struct Client {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    /// Behind a lock so the client can be shared (the receiver is taken once).
    messages: Mutex<Option<Receiver<Received>>>,
}

impl std::fmt::Debug for Client {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client")
            .field("counters", &self.counters())
            .finish()
    }
}

impl Client {
    /// Starts the client thread. It connects (and keeps reconnecting) by itself.
    pub fn start(config: ClientConfig, clock: Arc<dyn Clock>) -> Client {
        let shared = Arc::new(Shared {
            counters: Counters::default(),
            latest: LatestCell::new(),
            connected: AtomicBool::new(false),
            stop: AtomicBool::new(false),
            stream: Mutex::new(None),
            last_error: Mutex::new(None),
            watch: Watch::new(),
        });
        let (tx, rx) = if config.keep_messages > 0 {
            let (tx, rx) = sync_channel(config.keep_messages);
            (Some(tx), Some(rx))
        } else {
            (None, None)
        };
        let worker = Worker {
            shared: Arc::clone(&shared),
            device: config
                .device
                .as_deref()
                .and_then(|d| DeviceName::new(d).ok()),
            clock,
            tx,
            offset: OffsetEstimator::default(),
            last_ts: HashMap::new(),
            last_pose: None,
            config,
        };
        let thread = std::thread::Builder::new()
            .name("igtl-client".into())
            .spawn(move || worker.run())
            .ok();
        Client {
            shared,
            thread,
            messages: Mutex::new(rx),
        }
    }

    /// The counters so far.
    pub fn counters(&self) -> ClientCounters {
        self.shared.counters.snapshot()
    }

    /// Whether a connection is up.
    pub fn is_connected(&self) -> bool {
        self.shared.connected.load(Ordering::Relaxed)
    }

    /// The last stream error, in words.
    pub fn last_error(&self) -> Option<String> {
        self.shared.last_error.lock().ok().and_then(|e| e.clone())
    }

    /// Takes the channel of every decoded message (when `keep_messages > 0`; once), for whichever
    /// thread reads them.
    pub fn take_messages(&self) -> Option<Receiver<Received>> {
        self.messages
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .take()
    }

    /// A [`PoseSource`] over the configured device's newest pose.
    pub fn pose_source(&self) -> IgtlPoseSource {
        IgtlPoseSource {
            shared: Arc::clone(&self.shared),
            seen: 0,
        }
    }

    /// Sends a message to the server (e.g. a query); fails when not connected.
    pub fn send(&self, m: &Message) -> std::io::Result<()> {
        let guard = self
            .shared
            .stream
            .lock()
            .map_err(|_| std::io::Error::other("client lock poisoned"))?;
        match guard.as_ref() {
            Some(s) => {
                let mut s = s;
                s.write_all(&encode(m))
            }
            None => Err(std::io::Error::new(
                ErrorKind::NotConnected,
                "not connected",
            )),
        }
    }

    /// Stops the thread and closes the connection.
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Ok(g) = self.shared.stream.lock()
            && let Some(s) = g.as_ref()
        {
            s.shutdown(std::net::Shutdown::Both).ok();
        }
        if let Some(t) = self.thread.take() {
            t.join().ok();
        }
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// The configured device's newest pose, for the control loop. `latest` never blocks or locks.
#[derive(Debug)]
pub struct IgtlPoseSource {
    shared: Arc<Shared>,
    seen: u64,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared").finish_non_exhaustive()
    }
}

impl PoseSource for IgtlPoseSource {
    fn latest(&mut self) -> Option<PoseSample> {
        let (v, s) = self.shared.latest.read()?;
        if v == self.seen {
            return None;
        }
        self.seen = v;
        Some(s)
    }

    fn failures(&self) -> u64 {
        self.shared.watch.failures()
    }
}

struct Worker {
    shared: Arc<Shared>,
    config: ClientConfig,
    device: Option<DeviceName>,
    clock: Arc<dyn Clock>,
    tx: Option<SyncSender<Received>>,
    offset: OffsetEstimator,
    last_ts: HashMap<DeviceName, Timestamp>,
    last_pose: Option<Isometry3<f64>>,
}

fn resolve(addr: &str) -> Option<SocketAddr> {
    addr.to_socket_addrs().ok()?.next()
}

impl Worker {
    fn stopping(&self) -> bool {
        self.shared.stop.load(Ordering::Relaxed)
    }

    fn set_error(&self, e: String) {
        if let Ok(mut g) = self.shared.last_error.lock() {
            *g = Some(e);
        }
    }

    fn sleep(&self, d: Duration) {
        let end = Instant::now() + d;
        while !self.stopping() && Instant::now() < end {
            std::thread::sleep(Duration::from_millis(5).min(end - Instant::now()));
        }
    }

    fn run(mut self) {
        let shared = Arc::clone(&self.shared);
        let c = &shared.counters;
        let mut backoff = self.config.reconnect_initial;
        let mut decoder = Decoder::new(self.config.max_body);
        let mut buf = vec![0u8; 64 * 1024];
        while !self.stopping() {
            let stream = resolve(&self.config.addr)
                .ok_or_else(|| std::io::Error::new(ErrorKind::InvalidInput, "cannot resolve"))
                .and_then(|a| TcpStream::connect_timeout(&a, Duration::from_secs(1)));
            let mut stream = match stream {
                Ok(s) => s,
                Err(e) => {
                    c.connect_failures.fetch_add(1, Ordering::Relaxed);
                    self.set_error(format!("connect to {}: {e}", self.config.addr));
                    self.sleep(backoff);
                    backoff = (backoff * 2).min(self.config.reconnect_max);
                    continue;
                }
            };
            backoff = self.config.reconnect_initial;
            stream.set_nodelay(true).ok();
            stream
                .set_read_timeout(Some(Duration::from_millis(100)))
                .ok();
            if let (Ok(mut g), Ok(clone)) = (self.shared.stream.lock(), stream.try_clone()) {
                *g = Some(clone);
            }
            c.connections.fetch_add(1, Ordering::Relaxed);
            self.shared.connected.store(true, Ordering::Relaxed);
            decoder.reset();
            self.offset.reset();
            self.last_ts.clear();
            if let Some(res) = self.config.start_tdata {
                let m = Message::new(
                    "STT_TDATA",
                    "",
                    Body::StartTData {
                        resolution_ms: res,
                        coordinate: Name::<32>::empty(),
                    },
                );
                if let Ok(m) = m {
                    stream.write_all(&encode(&m)).ok();
                }
            }
            let served = shared.watch.run("igtl-client", || {
                self.serve(&mut stream, &mut decoder, &mut buf);
            });
            if served.is_none() {
                // A message the reader could not take (a bug it met, not a stream fault): the
                // connection is dropped, counted and named, and made again.
                c.reader_failures.fetch_add(1, Ordering::Relaxed);
                c.disconnects.fetch_add(1, Ordering::Relaxed);
                let what = self.shared.watch.last().unwrap_or_default();
                self.set_error(format!(
                    "{what}; the connection was dropped and is made again"
                ));
            }
            self.shared.connected.store(false, Ordering::Relaxed);
            if let Ok(mut g) = self.shared.stream.lock() {
                *g = None;
            }
            if !self.stopping() {
                self.sleep(backoff);
            }
        }
    }

    /// Reads and decodes one connection until it ends (closed, failed, a fatal error, or stop).
    fn serve(&mut self, stream: &mut TcpStream, decoder: &mut Decoder, buf: &mut [u8]) {
        let shared = Arc::clone(&self.shared);
        let c = &shared.counters;
        loop {
            if self.stopping() {
                break;
            }
            match stream.read(buf) {
                Ok(0) => {
                    if decoder.buffered() > 0 {
                        c.truncated.fetch_add(1, Ordering::Relaxed);
                        self.set_error(format!(
                            "connection closed in the middle of a message ({} bytes pending)",
                            decoder.buffered()
                        ));
                    }
                    c.disconnects.fetch_add(1, Ordering::Relaxed);
                    break;
                }
                Ok(n) => {
                    c.bytes.fetch_add(n as u64, Ordering::Relaxed);
                    decoder.feed(&buf[..n]);
                    while let Some(r) = decoder.next_message() {
                        match r {
                            Ok(m) => self.handle(m),
                            Err(e) => {
                                self.set_error(e.to_string());
                                if e.is_fatal() {
                                    c.fatal_errors.fetch_add(1, Ordering::Relaxed);
                                    c.disconnects.fetch_add(1, Ordering::Relaxed);
                                    return;
                                }
                                match e {
                                    crate::codec::DecodeError::Crc { .. } => {
                                        c.crc_errors.fetch_add(1, Ordering::Relaxed)
                                    }
                                    _ => c.malformed.fetch_add(1, Ordering::Relaxed),
                                };
                            }
                        }
                    }
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                    ) => {}
                Err(e) => {
                    if decoder.buffered() > 0 {
                        c.truncated.fetch_add(1, Ordering::Relaxed);
                    }
                    c.disconnects.fetch_add(1, Ordering::Relaxed);
                    self.set_error(format!("read: {e}"));
                    break;
                }
            }
        }
    }

    /// Acquisition time on our clock of a message received at `now`.
    fn acquired(&mut self, m: &Message, now: f64) -> f64 {
        let c = &self.shared.counters;
        if m.timestamp.is_none() {
            c.zero_timestamps.fetch_add(1, Ordering::Relaxed);
            return now;
        }
        if let Some(prev) = self.last_ts.insert(m.device, m.timestamp)
            && m.timestamp < prev
        {
            c.backwards_timestamps.fetch_add(1, Ordering::Relaxed);
            return now;
        }
        let wall = m.timestamp.to_secs_f64();
        match self.config.timestamps {
            TimestampMode::Synchronized => {
                // Our wall clock now, against our monotonic clock now.
                let ours = Timestamp::now().to_secs_f64();
                (wall + (now - ours)).min(now)
            }
            TimestampMode::Known(offset) => (wall + offset).min(now),
            TimestampMode::Estimated => {
                let o = self.offset.observe(now, wall);
                if o.step_s.is_some() {
                    c.clock_steps.fetch_add(1, Ordering::Relaxed);
                }
                (wall + o.offset_s - self.config.fixed_latency_s.max(0.0)).min(now)
            }
        }
    }

    fn handle(&mut self, m: Message) {
        let shared = Arc::clone(&self.shared);
        let c = &shared.counters;
        let now = self.clock.now_s();
        let acquired = self.acquired(&m, now);
        if let Some(device) = self.device {
            let floats = match &m.body {
                Body::Transform(f) if m.device == device => Some(Ok(*f)),
                Body::TData(tools) => tools
                    .iter()
                    .find(|t| t.name == device)
                    .map(|t| Ok(t.matrix)),
                Body::Position {
                    position,
                    quaternion,
                } if m.device == device => Some(Err((*position, *quaternion))),
                _ => None,
            };
            if let Some(f) = floats {
                let pose = match f {
                    Ok(f) => pose_of(&f).ok(),
                    Err((p, q)) => {
                        let q = Quaternion::new(
                            f64::from(q[3]),
                            f64::from(q[0]),
                            f64::from(q[1]),
                            f64::from(q[2]),
                        );
                        (q.norm() > 0.5).then(|| {
                            Isometry3::from_parts(
                                Translation3::new(
                                    f64::from(p[0]) / 1000.0,
                                    f64::from(p[1]) / 1000.0,
                                    f64::from(p[2]) / 1000.0,
                                ),
                                UnitQuaternion::from_quaternion(q),
                            )
                        })
                    }
                };
                if pose.is_none() {
                    c.non_rigid.fetch_add(1, Ordering::Relaxed);
                }
                let valid = pose.is_some() && status_valid(&m);
                let pose = pose.or(self.last_pose).unwrap_or_else(Isometry3::identity);
                if valid {
                    self.last_pose = Some(pose);
                } else {
                    c.invalid_poses.fetch_add(1, Ordering::Relaxed);
                }
                self.shared.latest.publish(&PoseSample {
                    tracker_from_marker: pose,
                    acquired_s: acquired,
                    valid,
                    error_m: f64::NAN,
                });
                c.poses.fetch_add(1, Ordering::Relaxed);
            }
        }
        // Counted once handled: whoever waits for a count (a stepped simulation) then finds the
        // pose published, never the one before it.
        c.messages.fetch_add(1, Ordering::Relaxed);
        match &m.body {
            Body::Transform(_) => c.transforms.fetch_add(1, Ordering::Release),
            Body::Position { .. } => c.positions.fetch_add(1, Ordering::Release),
            Body::TData(_) => c.tdata.fetch_add(1, Ordering::Release),
            Body::Status(_) => c.statuses.fetch_add(1, Ordering::Relaxed),
            Body::String { .. } => c.strings.fetch_add(1, Ordering::Relaxed),
            Body::StartTData { .. } | Body::RtsTData { .. } | Body::Query(_) => {
                c.queries.fetch_add(1, Ordering::Relaxed)
            }
            Body::Unknown { .. } => c.unknown.fetch_add(1, Ordering::Relaxed),
        };
        if let Some(tx) = &self.tx {
            match tx.try_send(Received {
                message: m,
                received_s: now,
                acquired_s: acquired,
            }) {
                Ok(()) | Err(TrySendError::Disconnected(_)) => {}
                Err(TrySendError::Full(_)) => {
                    c.consumer_drops.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }
}

/// Whether a message's status metadata (as PLUS sends it) says the pose is valid: `TransformStatus`
/// must be "OK" and `TransformValid` "true"/"1" when present.
pub fn status_valid(m: &Message) -> bool {
    let status_ok = m
        .meta("TransformStatus")
        .is_none_or(|s| s.eq_ignore_ascii_case("OK"));
    let valid_ok = m
        .meta("TransformValid")
        .is_none_or(|s| s.eq_ignore_ascii_case("true") || s == "1");
    status_ok && valid_ok
}
