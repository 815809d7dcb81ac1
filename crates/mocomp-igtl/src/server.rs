//! The OpenIGTLink server: streams messages to any number of clients (3D Slicer, PLUS-style
//! consumers), answers their GET_ queries from the newest message of each type and device,
//! starts and stops TDATA streams on STT_/STP_TDATA, and drops a client that does not keep up
//! instead of stalling the others.
//!
//! Each client has a writer thread fed by a bounded queue; [`Server::send`] encodes once and
//! offers the bytes to every queue without blocking. A full queue means the client stopped
//! reading: it is disconnected and counted.

use crate::codec::{DEFAULT_MAX_BODY, Decoder, encode};
use crate::message::{Body, Message, QueryKind, QueryTarget, Status, status_code};
use crate::name::{DeviceName, Name, TypeName};
use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

/// Server settings.
#[derive(Debug, Clone, Copy)]
pub struct ServerConfig {
    /// Messages queued per client before it counts as too slow and is dropped.
    pub queue: usize,
    /// Largest body accepted from a client.
    pub max_body: u64,
    /// Send TDATA to every client, not only to those that asked with STT_TDATA (some receivers,
    /// like the OpenIGTLink examples, never ask).
    pub push_tdata: bool,
}

impl Default for ServerConfig {
    fn default() -> Self {
        Self {
            queue: 1024,
            max_body: DEFAULT_MAX_BODY,
            push_tdata: false,
        }
    }
}

/// What the server counted.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ServerCounters {
    /// Clients accepted.
    pub accepted: u64,
    /// Clients dropped because their queue was full.
    pub dropped_slow: u64,
    /// Clients that went away.
    pub disconnected: u64,
    /// Messages offered to clients (one per client per message).
    pub sent: u64,
    /// Queries answered.
    pub queries: u64,
    /// Bad messages received from clients (CRC, layout, garbage).
    pub bad_input: u64,
}

#[derive(Debug, Default)]
struct Counters {
    accepted: AtomicU64,
    dropped_slow: AtomicU64,
    disconnected: AtomicU64,
    sent: AtomicU64,
    queries: AtomicU64,
    bad_input: AtomicU64,
}

type Bytes = Arc<Vec<u8>>;

#[derive(Debug)]
struct Slot {
    tx: SyncSender<Bytes>,
    tdata: Arc<AtomicBool>,
    stream: TcpStream,
    alive: Arc<AtomicBool>,
    /// Messages queued for this client and not yet written to its socket.
    pending: Arc<AtomicU64>,
}

#[derive(Debug)]
struct Shared {
    clients: Mutex<Vec<Slot>>,
    latest: Mutex<Vec<(TypeName, DeviceName, Bytes)>>,
    counters: Counters,
    stop: AtomicBool,
    config: ServerConfig,
}

/// A running server. Dropping it stops accepting and disconnects every client.
#[derive(Debug)]
pub struct Server {
    shared: Arc<Shared>,
    addr: SocketAddr,
    accept: Option<JoinHandle<()>>,
}

impl Server {
    /// Listens on `addr` (e.g. `127.0.0.1:18944`, or port 0 for any free port).
    pub fn bind(addr: &str, config: ServerConfig) -> std::io::Result<Server> {
        let listener = TcpListener::bind(addr)?;
        listener.set_nonblocking(true)?;
        let local = listener.local_addr()?;
        let shared = Arc::new(Shared {
            clients: Mutex::new(Vec::new()),
            latest: Mutex::new(Vec::new()),
            counters: Counters::default(),
            stop: AtomicBool::new(false),
            config,
        });
        let s = Arc::clone(&shared);
        let accept = std::thread::Builder::new()
            .name("igtl-accept".into())
            .spawn(move || accept_loop(listener, s))?;
        Ok(Server {
            shared,
            addr: local,
            accept: Some(accept),
        })
    }

    /// The address it listens on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Clients connected now.
    pub fn client_count(&self) -> usize {
        self.shared.clients.lock().map(|c| c.len()).unwrap_or(0)
    }

    /// The counters so far.
    pub fn counters(&self) -> ServerCounters {
        let c = &self.shared.counters;
        ServerCounters {
            accepted: c.accepted.load(Ordering::Relaxed),
            dropped_slow: c.dropped_slow.load(Ordering::Relaxed),
            disconnected: c.disconnected.load(Ordering::Relaxed),
            sent: c.sent.load(Ordering::Relaxed),
            queries: c.queries.load(Ordering::Relaxed),
            bad_input: c.bad_input.load(Ordering::Relaxed),
        }
    }

    /// Sends a message to every client (TDATA only to clients that started a TDATA stream), and
    /// keeps it as the answer to GET_ queries for its type and device. Never blocks on a client.
    pub fn send(&self, m: &Message) {
        self.send_bytes(m.type_name, m.device, Arc::new(encode(m)));
    }

    /// Like [`Server::send`] for bytes already encoded (`type_name` and `device` as in them).
    pub fn send_bytes(&self, type_name: TypeName, device: DeviceName, bytes: Bytes) {
        if let Ok(mut latest) = self.shared.latest.lock() {
            match latest
                .iter_mut()
                .find(|(t, d, _)| *t == type_name && *d == device)
            {
                Some(e) => e.2 = Arc::clone(&bytes),
                None => latest.push((type_name, device, Arc::clone(&bytes))),
            }
        }
        let tdata = type_name == "TDATA" && !self.shared.config.push_tdata;
        let c = &self.shared.counters;
        if let Ok(mut clients) = self.shared.clients.lock() {
            clients.retain(|slot| {
                if !slot.alive.load(Ordering::Relaxed) {
                    c.disconnected.fetch_add(1, Ordering::Relaxed);
                    return false;
                }
                if tdata && !slot.tdata.load(Ordering::Relaxed) {
                    return true;
                }
                slot.pending.fetch_add(1, Ordering::Relaxed);
                match slot.tx.try_send(Arc::clone(&bytes)) {
                    Ok(()) => {
                        c.sent.fetch_add(1, Ordering::Relaxed);
                        true
                    }
                    Err(TrySendError::Full(_)) => {
                        slot.pending.fetch_sub(1, Ordering::Relaxed);
                        c.dropped_slow.fetch_add(1, Ordering::Relaxed);
                        slot.alive.store(false, Ordering::Relaxed);
                        slot.stream.shutdown(std::net::Shutdown::Both).ok();
                        false
                    }
                    Err(TrySendError::Disconnected(_)) => {
                        slot.pending.fetch_sub(1, Ordering::Relaxed);
                        c.disconnected.fetch_add(1, Ordering::Relaxed);
                        false
                    }
                }
            });
        }
    }

    /// Waits until every message sent so far has been written to the sockets of the clients
    /// still connected, or `timeout` has passed; returns whether everything was written. For a
    /// sender about to close that must not cut its last messages off.
    pub fn flush(&self, timeout: Duration) -> bool {
        let end = std::time::Instant::now() + timeout;
        loop {
            let pending = self.shared.clients.lock().map_or(0, |c| {
                c.iter()
                    .filter(|s| s.alive.load(Ordering::Relaxed))
                    .map(|s| s.pending.load(Ordering::Relaxed))
                    .sum::<u64>()
            });
            if pending == 0 {
                return true;
            }
            if std::time::Instant::now() >= end {
                return false;
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    /// Stops the server and disconnects every client.
    pub fn stop(mut self) {
        self.shutdown();
    }

    fn shutdown(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Ok(mut clients) = self.shared.clients.lock() {
            for s in clients.drain(..) {
                s.alive.store(false, Ordering::Relaxed);
                s.stream.shutdown(std::net::Shutdown::Both).ok();
            }
        }
        if let Some(t) = self.accept.take() {
            t.join().ok();
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.shutdown();
    }
}

fn accept_loop(listener: TcpListener, shared: Arc<Shared>) {
    let mut next_id = 0u64;
    while !shared.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                next_id += 1;
                if let Err(e) = add_client(&shared, stream, next_id) {
                    // The client went away before it was set up; nothing to keep.
                    drop(e);
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(2))
            }
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

fn add_client(shared: &Arc<Shared>, stream: TcpStream, id: u64) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    let (tx, rx) = sync_channel::<Bytes>(shared.config.queue);
    let tdata = Arc::new(AtomicBool::new(false));
    let alive = Arc::new(AtomicBool::new(true));
    let pending = Arc::new(AtomicU64::new(0));
    let writer_stream = stream.try_clone()?;
    let reader_stream = stream.try_clone()?;
    {
        let (alive, pending) = (Arc::clone(&alive), Arc::clone(&pending));
        std::thread::Builder::new()
            .name(format!("igtl-writer-{id}"))
            .spawn(move || writer(writer_stream, rx, alive, pending))?;
    }
    {
        let shared = Arc::clone(shared);
        let (tx, tdata, alive) = (tx.clone(), Arc::clone(&tdata), Arc::clone(&alive));
        let pending = Arc::clone(&pending);
        std::thread::Builder::new()
            .name(format!("igtl-reader-{id}"))
            .spawn(move || reader(reader_stream, shared, tx, tdata, alive, pending))?;
    }
    shared.counters.accepted.fetch_add(1, Ordering::Relaxed);
    if let Ok(mut clients) = shared.clients.lock() {
        clients.push(Slot {
            tx,
            tdata,
            stream,
            alive,
            pending,
        });
    }
    Ok(())
}

fn writer(
    mut stream: TcpStream,
    rx: Receiver<Bytes>,
    alive: Arc<AtomicBool>,
    pending: Arc<AtomicU64>,
) {
    while alive.load(Ordering::Relaxed) {
        match rx.recv_timeout(Duration::from_millis(100)) {
            Ok(bytes) => {
                let ok = stream.write_all(&bytes).is_ok();
                pending.fetch_sub(1, Ordering::Relaxed);
                if !ok {
                    break;
                }
            }
            Err(RecvTimeoutError::Timeout) => {}
            Err(RecvTimeoutError::Disconnected) => break,
        }
    }
    alive.store(false, Ordering::Relaxed);
    stream.shutdown(std::net::Shutdown::Both).ok();
}

fn status(device: DeviceName, code: u16, text: &str) -> Message {
    Message {
        header_version: 1,
        type_name: TypeName::new("STATUS").unwrap_or(TypeName::empty()),
        device,
        timestamp: crate::timestamp::Timestamp::now(),
        message_id: 0,
        metadata: Vec::new(),
        body: Body::Status(Status {
            code,
            subcode: 0,
            error_name: Name::<20>::empty(),
            message: text.to_string(),
        }),
    }
}

fn reader(
    mut stream: TcpStream,
    shared: Arc<Shared>,
    tx: SyncSender<Bytes>,
    tdata: Arc<AtomicBool>,
    alive: Arc<AtomicBool>,
    pending: Arc<AtomicU64>,
) {
    stream
        .set_read_timeout(Some(Duration::from_millis(100)))
        .ok();
    let mut decoder = Decoder::new(shared.config.max_body);
    let mut buf = vec![0u8; 16 * 1024];
    let reply = |bytes: Bytes| {
        pending.fetch_add(1, Ordering::Relaxed);
        if tx.try_send(bytes).is_err() {
            pending.fetch_sub(1, Ordering::Relaxed);
        }
    };
    while alive.load(Ordering::Relaxed) && !shared.stop.load(Ordering::Relaxed) {
        match stream.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                decoder.feed(&buf[..n]);
                while let Some(r) = decoder.next_message() {
                    let m = match r {
                        Ok(m) => m,
                        Err(e) => {
                            shared.counters.bad_input.fetch_add(1, Ordering::Relaxed);
                            if e.is_fatal() {
                                alive.store(false, Ordering::Relaxed);
                                return;
                            }
                            continue;
                        }
                    };
                    let Some((kind, target)) = m.query() else {
                        continue;
                    };
                    shared.counters.queries.fetch_add(1, Ordering::Relaxed);
                    match (kind, target) {
                        (
                            QueryKind::Get,
                            QueryTarget::Transform | QueryTarget::TData | QueryTarget::Status,
                        ) => {
                            let want = match target {
                                QueryTarget::Transform => "TRANSFORM",
                                QueryTarget::TData => "TDATA",
                                _ => "STATUS",
                            };
                            let found = shared.latest.lock().ok().and_then(|l| {
                                l.iter()
                                    .find(|(t, d, _)| {
                                        *t == want
                                            && (m.device.as_str().is_empty() || *d == m.device)
                                    })
                                    .map(|e| Arc::clone(&e.2))
                            });
                            match found {
                                Some(b) => reply(b),
                                None => reply(Arc::new(encode(&status(
                                    m.device,
                                    status_code::NOT_FOUND,
                                    &format!("no {want} for {:?}", m.device.as_str()),
                                )))),
                            }
                        }
                        (QueryKind::Start | QueryKind::Stop, QueryTarget::TData) => {
                            tdata.store(kind == QueryKind::Start, Ordering::Relaxed);
                            if let Ok(mut r) = Message::new(
                                "RTS_TDATA",
                                m.device.as_str(),
                                Body::RtsTData { status: 0 },
                            ) {
                                r.timestamp = crate::timestamp::Timestamp::now();
                                reply(Arc::new(encode(&r)));
                            }
                        }
                        (QueryKind::Reply, _) => {}
                        _ => reply(Arc::new(encode(&status(
                            m.device,
                            status_code::UNKNOWN_INSTRUCTION,
                            &format!("{} is not supported", m.type_name),
                        )))),
                    }
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                ) => {}
            Err(_) => break,
        }
    }
    alive.store(false, Ordering::Relaxed);
}
