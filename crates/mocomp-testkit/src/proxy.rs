//! A fault-injecting TCP relay: it sits between a client (mocomp) and a server (the controller,
//! the tracker server) on loopback and, on command from the test, does to the bytes what a real
//! network and a real cell do to them: delay and jitter, a stall of N ms, a cut (nothing passes
//! until it is restored, as when a cable is pulled and put back before TCP gives up), a reset of
//! every connection (RST both ways), corrupted bytes and dropped bytes (a stream whose framing
//! is broken).
//!
//! This kernel has neither `netem` nor netfilter, so faults are made here, in user space: each
//! connection is two pumps, and each pump is a reader that stamps every chunk with its arrival
//! time and a writer that sends it on when the faults in force let it. Bytes held back by a stall
//! or a cut are kept, in order, and sent on when it ends: TCP's own behaviour over a link that
//! comes back before its retransmission gives up.

use crate::SplitMix64;
use std::collections::VecDeque;
use std::io::{ErrorKind, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The pumps' `SCHED_FIFO` priority: the simulated controller's (below the loop's 50).
const PUMP_PRIORITY: u8 = 49;

/// Which way bytes travel through the relay.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// From the client to the server (mocomp's commands, its requests).
    Upstream,
    /// From the server to the client (the controller's state, the tracker's poses).
    Downstream,
}

impl Direction {
    fn index(self) -> usize {
        match self {
            Self::Upstream => 0,
            Self::Downstream => 1,
        }
    }
}

/// The faults in force, per direction where it matters.
#[derive(Debug, Default)]
struct Faults {
    delay: Duration,
    jitter: Duration,
    /// Nothing passes (in this direction) before this instant.
    stalled_until: [Option<Instant>; 2],
    /// Nothing passes, and no new connection reaches the server, until restored.
    cut: bool,
    /// Bytes still to be corrupted (each XORed with a seeded non-zero value).
    corrupt: [usize; 2],
    /// Bytes still to be dropped.
    drop: [usize; 2],
    rng: SplitMix64,
}

/// What a pump's writer waits on and what the test changes.
struct Shared {
    faults: Mutex<Faults>,
    changed: Condvar,
    stop: AtomicBool,
    /// Every open connection: its reset flag and both of its sockets, for a reset.
    open: Mutex<Vec<Conn>>,
    connections: AtomicU64,
    /// Bytes relayed per direction.
    bytes: [AtomicU64; 2],
}

/// An open connection as a reset sees it.
struct Conn {
    reset: Arc<AtomicBool>,
    client: TcpStream,
    server: TcpStream,
}

impl Shared {
    fn open(&self) -> MutexGuard<'_, Vec<Conn>> {
        self.open.lock().unwrap_or_else(PoisonError::into_inner)
    }

    fn faults(&self) -> MutexGuard<'_, Faults> {
        self.faults.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

/// A relay listening on `addr` that forwards every connection to `upstream`, faults injected on
/// command. Stops (and closes every connection) when dropped.
pub struct FaultProxy {
    addr: SocketAddr,
    shared: Arc<Shared>,
    accept: Option<JoinHandle<()>>,
}

impl std::fmt::Debug for FaultProxy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FaultProxy")
            .field("addr", &self.addr)
            .finish_non_exhaustive()
    }
}

impl FaultProxy {
    /// Listens on `listen` (port 0: any) and relays to `upstream`; `seed` makes jitter and
    /// corruption reproduce.
    pub fn start(listen: SocketAddr, upstream: SocketAddr, seed: u64) -> std::io::Result<Self> {
        let listener = TcpListener::bind(listen)?;
        let addr = listener.local_addr()?;
        // Non-blocking accept, so that dropping the proxy ends the accept thread.
        listener.set_nonblocking(true)?;
        let shared = Arc::new(Shared {
            faults: Mutex::new(Faults {
                rng: SplitMix64(seed),
                ..Faults::default()
            }),
            changed: Condvar::new(),
            stop: AtomicBool::new(false),
            open: Mutex::new(Vec::new()),
            connections: AtomicU64::new(0),
            bytes: [AtomicU64::new(0), AtomicU64::new(0)],
        });
        let accept = {
            let shared = Arc::clone(&shared);
            std::thread::Builder::new()
                .name("fault-proxy".into())
                .spawn(move || accept_loop(&listener, upstream, &shared))?
        };
        Ok(Self {
            addr,
            shared,
            accept: Some(accept),
        })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Connections accepted so far.
    pub fn connections(&self) -> u64 {
        self.shared.connections.load(Ordering::Relaxed)
    }

    /// Bytes relayed so far in `dir` (counted as they are handed on: bytes a peer has
    /// received are counted).
    pub fn bytes(&self, dir: Direction) -> u64 {
        self.shared.bytes[dir.index()].load(Ordering::Relaxed)
    }

    fn change(&self, f: impl FnOnce(&mut Faults)) {
        f(&mut self.shared.faults());
        self.shared.changed.notify_all();
    }

    /// Every chunk is held `delay` plus up to `jitter` (uniform, seeded) after it arrived; order
    /// is kept, as on a TCP stream.
    pub fn set_delay(&self, delay: Duration, jitter: Duration) {
        self.change(|f| {
            f.delay = delay;
            f.jitter = jitter;
        });
    }

    /// Nothing passes either way for `pause` from now; what arrives meanwhile is sent on after.
    pub fn stall(&self, pause: Duration) {
        self.stall_one(Direction::Upstream, pause);
        self.stall_one(Direction::Downstream, pause);
    }

    /// Nothing passes in `dir` for `pause` from now.
    pub fn stall_one(&self, dir: Direction, pause: Duration) {
        let until = Instant::now() + pause;
        self.change(|f| f.stalled_until[dir.index()] = Some(until));
    }

    /// Nothing passes either way, and new connections wait, until [`Self::restore`].
    pub fn cut(&self) {
        self.change(|f| f.cut = true);
    }

    /// Ends a [`Self::cut`]: what was held back goes on, in order.
    pub fn restore(&self) {
        self.change(|f| f.cut = false);
    }

    /// Resets every open connection (an RST to both the client and the server, as a router that
    /// lost the connection's state does); new connections are relayed as before.
    pub fn reset(&self) {
        let mut open = self.shared.open();
        for c in open.drain(..) {
            arm_rst(&c.client);
            arm_rst(&c.server);
            c.reset.store(true, Ordering::Relaxed);
        }
        self.shared.changed.notify_all();
    }

    /// The next `n` bytes in `dir` are each XORed with a seeded non-zero byte.
    pub fn corrupt(&self, dir: Direction, n: usize) {
        self.change(|f| f.corrupt[dir.index()] += n);
    }

    /// The next `n` bytes in `dir` vanish (the stream's framing after them is broken).
    pub fn drop_bytes(&self, dir: Direction, n: usize) {
        self.change(|f| f.drop[dir.index()] += n);
    }

    /// Whether the corruption and dropping asked for have all been done.
    pub fn faults_spent(&self) -> bool {
        let f = self.shared.faults();
        f.corrupt == [0, 0] && f.drop == [0, 0]
    }
}

impl Drop for FaultProxy {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        self.shared.changed.notify_all();
        {
            let mut open = self.shared.open();
            for c in open.drain(..) {
                c.client.shutdown(Shutdown::Both).ok();
                c.server.shutdown(Shutdown::Both).ok();
            }
        }
        if let Some(t) = self.accept.take() {
            t.join().ok();
        }
    }
}

/// Makes the close of `s` an RST (SO_LINGER on, zero timeout): it goes out when the last handle
/// to the socket closes, which the pumps do within a few milliseconds of seeing the reset flag.
/// A shutdown would send a FIN first, an orderly end, which is not what a reset is.
fn arm_rst(s: &TcpStream) {
    use nix::sys::socket::{setsockopt, sockopt};
    let linger = nix::libc::linger {
        l_onoff: 1,
        l_linger: 0,
    };
    setsockopt(s, sockopt::Linger, &linger).ok();
}

fn accept_loop(listener: &TcpListener, upstream: SocketAddr, shared: &Arc<Shared>) {
    let mut pumps: Vec<JoinHandle<()>> = Vec::new();
    while !shared.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((client, _)) => {
                shared.connections.fetch_add(1, Ordering::Relaxed);
                let shared = Arc::clone(shared);
                if let Ok(t) = std::thread::Builder::new()
                    .name("fault-proxy-conn".into())
                    .spawn(move || relay(client, upstream, &shared))
                {
                    pumps.push(t);
                }
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(2));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(2)),
        }
        pumps.retain(|t| !t.is_finished());
    }
    for t in pumps {
        t.join().ok();
    }
}

/// One connection: waits out a cut, connects to the server, pumps both ways until either side
/// closes or the proxy stops.
fn relay(client: TcpStream, upstream: SocketAddr, shared: &Arc<Shared>) {
    {
        let mut f = shared.faults();
        while f.cut && !shared.stop.load(Ordering::Relaxed) {
            f = shared
                .changed
                .wait_timeout(f, Duration::from_millis(20))
                .unwrap_or_else(PoisonError::into_inner)
                .0;
        }
    }
    client.set_nonblocking(false).ok();
    let Ok(server) = TcpStream::connect_timeout(&upstream, Duration::from_secs(2)) else {
        // The server refused: so does the relay, abruptly, as a refused connection is.
        arm_rst(&client);
        return;
    };
    client.set_nodelay(true).ok();
    server.set_nodelay(true).ok();
    let handles = [&client, &server].map(|s| s.try_clone());
    let [Ok(c2), Ok(s2)] = handles else {
        return;
    };
    let reset = Arc::new(AtomicBool::new(false));
    shared.open().push(Conn {
        reset: Arc::clone(&reset),
        client: c2,
        server: s2,
    });
    let (Ok(client_w), Ok(server_w)) = (client.try_clone(), server.try_clone()) else {
        return;
    };
    let up = {
        let shared = Arc::clone(shared);
        let reset = Arc::clone(&reset);
        std::thread::spawn(move || pump(client, server_w, Direction::Upstream, &shared, &reset))
    };
    pump(server, client_w, Direction::Downstream, shared, &reset);
    up.join().ok();
    // Closed by either end: forget it (a reset has already).
    shared.open().retain(|c| !Arc::ptr_eq(&c.reset, &reset));
}

/// The chunks read and not yet sent on, with the time each is due.
struct Queue {
    chunks: VecDeque<(Instant, Vec<u8>)>,
    closed: bool,
}

/// `from` → `to` in `dir`: a reader thread queues what arrives, this thread sends it when due.
fn pump(
    from: TcpStream,
    mut to: TcpStream,
    dir: Direction,
    shared: &Arc<Shared>,
    reset: &Arc<AtomicBool>,
) {
    // The relay stands for the network, not for another process competing for the CPU: its
    // pumps run at the simulated controller's real-time priority where the system allows, so
    // a busy machine does not turn a 10 ms stall into a 60 ms one (and trip the watchdog).
    mocomp_rt::set_fifo(PUMP_PRIORITY).ok();
    let queue = Arc::new((
        Mutex::new(Queue {
            chunks: VecDeque::new(),
            closed: false,
        }),
        Condvar::new(),
    ));
    let reader = {
        let queue = Arc::clone(&queue);
        let shared = Arc::clone(shared);
        let reset = Arc::clone(reset);
        std::thread::spawn(move || {
            read_into(from, &queue, &shared, &reset);
        })
    };
    let d = dir.index();
    while let Some(mut bytes) = next_chunk(&queue, shared, reset, d) {
        damage(shared, d, &mut bytes);
        if bytes.is_empty() {
            continue;
        }
        // Counted before they are handed on: whoever has received them (the echo's answer
        // back at the test, say) must find them counted, and this thread may be descheduled
        // between the write and any count after it (a non-root run beside stress-ng read
        // 9,800 of 10,000 bytes so).
        shared.bytes[d].fetch_add(bytes.len() as u64, Ordering::Relaxed);
        if to.write_all(&bytes).is_err() {
            shared.bytes[d].fetch_sub(bytes.len() as u64, Ordering::Relaxed);
            break;
        }
    }
    if !reset.load(Ordering::Relaxed) {
        to.shutdown(Shutdown::Write).ok();
    }
    reader.join().ok();
}

/// The reader's side: queues each chunk read from `from` with the time it is due (the delay and
/// jitter of the faults, order kept) until the stream ends, the relay stops or the connection is
/// reset.
fn read_into(
    mut from: TcpStream,
    queue: &(Mutex<Queue>, Condvar),
    shared: &Shared,
    reset: &AtomicBool,
) {
    mocomp_rt::set_fifo(PUMP_PRIORITY).ok();
    let mut buf = vec![0u8; 64 * 1024];
    // Short: a reset is seen within this.
    from.set_read_timeout(Some(Duration::from_millis(5))).ok();
    let mut last_due = Instant::now();
    loop {
        if shared.stop.load(Ordering::Relaxed) || reset.load(Ordering::Relaxed) {
            break;
        }
        match from.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                let now = Instant::now();
                let due = {
                    let mut f = shared.faults();
                    let jitter = if f.jitter.is_zero() {
                        Duration::ZERO
                    } else {
                        let r = f.rng.next_u64();
                        let nanos = u64::try_from(f.jitter.as_nanos()).unwrap_or(u64::MAX);
                        Duration::from_nanos(r % nanos.max(1))
                    };
                    // Order is kept: no chunk is due before the one ahead of it.
                    (now + f.delay + jitter).max(last_due)
                };
                last_due = due;
                let (q, cv) = queue;
                q.lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .chunks
                    .push_back((due, buf[..n].to_vec()));
                cv.notify_all();
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {}
            Err(_) => break,
        }
    }
    let (q, cv) = queue;
    q.lock().unwrap_or_else(PoisonError::into_inner).closed = true;
    cv.notify_all();
    // The other way learns of an orderly end through its own read; a reset closes
    // without a FIN.
    if !reset.load(Ordering::Relaxed) {
        from.shutdown(Shutdown::Both).ok();
    }
}

/// The next chunk, once it is due and the faults let it pass; `None` once the stream has ended,
/// the relay stops or the connection is reset.
fn next_chunk(
    queue: &(Mutex<Queue>, Condvar),
    shared: &Shared,
    reset: &AtomicBool,
    d: usize,
) -> Option<Vec<u8>> {
    let (q, cv) = queue;
    let mut g = q.lock().unwrap_or_else(PoisonError::into_inner);
    loop {
        if shared.stop.load(Ordering::Relaxed) || reset.load(Ordering::Relaxed) {
            break None;
        }
        let now = Instant::now();
        let blocked_until = {
            let f = shared.faults();
            if f.cut {
                Some(now + Duration::from_millis(5))
            } else {
                f.stalled_until[d].filter(|t| *t > now)
            }
        };
        let wait = match (g.chunks.front(), blocked_until) {
            (_, Some(t)) => t - now,
            (Some((due, _)), None) if *due > now => *due - now,
            (Some(_), None) => break g.chunks.pop_front().map(|c| c.1),
            (None, None) if g.closed => break None,
            (None, None) => Duration::from_millis(5),
        };
        g = cv
            .wait_timeout(g, wait.min(Duration::from_millis(5)))
            .unwrap_or_else(PoisonError::into_inner)
            .0;
    }
}

/// The bytes the faults drop from the front of a chunk and those they corrupt, in direction `d`.
fn damage(shared: &Shared, d: usize, bytes: &mut Vec<u8>) {
    let mut f = shared.faults();
    let drop = f.drop[d].min(bytes.len());
    if drop > 0 {
        f.drop[d] -= drop;
        bytes.drain(..drop);
    }
    let n = f.corrupt[d].min(bytes.len());
    for b in bytes.iter_mut().take(n) {
        // Never XOR with 0: every byte asked for is changed.
        *b ^= (f.rng.next_u64() % 255 + 1) as u8;
    }
    f.corrupt[d] -= n;
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use std::net::{IpAddr, Ipv4Addr};

    fn loopback() -> SocketAddr {
        SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 0)
    }

    /// An echo server: what it reads it writes back.
    fn echo() -> SocketAddr {
        let l = TcpListener::bind(loopback()).unwrap();
        let addr = l.local_addr().unwrap();
        std::thread::spawn(move || {
            for s in l.incoming() {
                let Ok(mut s) = s else { break };
                std::thread::spawn(move || {
                    let mut buf = [0u8; 4096];
                    while let Ok(n) = s.read(&mut buf) {
                        if n == 0 || s.write_all(&buf[..n]).is_err() {
                            break;
                        }
                    }
                });
            }
        });
        addr
    }

    fn round_trip(c: &mut TcpStream, msg: &[u8]) -> (Vec<u8>, Duration) {
        let t0 = Instant::now();
        c.write_all(msg).unwrap();
        let mut got = vec![0u8; msg.len()];
        c.read_exact(&mut got).unwrap();
        (got, t0.elapsed())
    }

    fn client(p: &FaultProxy) -> TcpStream {
        let c = TcpStream::connect(p.addr()).unwrap();
        c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        c
    }

    #[test]
    fn bytes_pass_unchanged_and_in_order_without_faults() {
        let p = FaultProxy::start(loopback(), echo(), 1).unwrap();
        let mut c = client(&p);
        for k in 0..50u8 {
            let msg: Vec<u8> = (0..200).map(|i| k.wrapping_add(i)).collect();
            assert_eq!(round_trip(&mut c, &msg).0, msg);
        }
        assert_eq!(p.connections(), 1);
        assert_eq!(p.bytes(Direction::Upstream), 50 * 200);
    }

    #[test]
    fn a_stall_holds_the_bytes_then_delivers_them_in_order() {
        let p = FaultProxy::start(loopback(), echo(), 2).unwrap();
        let mut c = client(&p);
        round_trip(&mut c, b"warm");
        p.stall(Duration::from_secs(1));
        let (got, took) = round_trip(&mut c, b"held back");
        assert_eq!(got, b"held back");
        // A busy machine only makes it longer.
        assert!(took >= Duration::from_millis(990), "{took:?}");
        // After it, not held again: far below another stall's second (the margin only catches
        // a relay that stalls again, not a slow machine).
        let (_, took) = round_trip(&mut c, b"after");
        assert!(took < Duration::from_millis(500), "{took:?}");
    }

    #[test]
    fn a_delay_with_jitter_keeps_the_order() {
        let p = FaultProxy::start(loopback(), echo(), 3).unwrap();
        p.set_delay(Duration::from_millis(20), Duration::from_millis(10));
        let mut c = client(&p);
        let msgs: Vec<Vec<u8>> = (0..20u8).map(|k| vec![k; 10]).collect();
        for m in &msgs {
            c.write_all(m).unwrap();
        }
        let mut got = vec![0u8; 200];
        let t0 = Instant::now();
        c.read_exact(&mut got).unwrap();
        assert!(t0.elapsed() >= Duration::from_millis(20));
        assert_eq!(got, msgs.concat());
    }

    #[test]
    fn a_cut_holds_everything_and_new_connections_until_restored() {
        let p = FaultProxy::start(loopback(), echo(), 4).unwrap();
        let mut c = client(&p);
        round_trip(&mut c, b"before");
        p.cut();
        c.write_all(b"during").unwrap();
        c.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        let mut buf = [0u8; 6];
        let e = c.read_exact(&mut buf).unwrap_err();
        assert!(
            matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut),
            "{e}"
        );
        p.restore();
        c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        c.read_exact(&mut buf).unwrap();
        assert_eq!(&buf, b"during");
    }

    #[test]
    fn a_reset_breaks_the_connection_and_a_new_one_is_relayed() {
        let p = FaultProxy::start(loopback(), echo(), 5).unwrap();
        let mut c = client(&p);
        round_trip(&mut c, b"x");
        p.reset();
        // The client sees a reset (not an orderly close, not a hang).
        let mut buf = [0u8; 1];
        let r = c.read(&mut buf);
        assert!(
            matches!(&r, Err(e) if e.kind() == ErrorKind::ConnectionReset),
            "{r:?}"
        );
        let mut c = client(&p);
        assert_eq!(round_trip(&mut c, b"again").0, b"again");
        assert_eq!(p.connections(), 2);
    }

    #[test]
    fn corruption_changes_exactly_the_bytes_asked_for_and_dropping_removes_them() {
        let p = FaultProxy::start(loopback(), echo(), 6).unwrap();
        let mut c = client(&p);
        round_trip(&mut c, b"warm");
        p.corrupt(Direction::Downstream, 3);
        let msg = b"0123456789";
        let (got, _) = round_trip(&mut c, msg);
        let changed = got.iter().zip(msg).filter(|(a, b)| a != b).count();
        assert_eq!(changed, 3, "{got:?}");
        assert!(p.faults_spent());
        p.drop_bytes(Direction::Upstream, 4);
        c.write_all(b"abcdefgh").unwrap();
        let mut got = [0u8; 4];
        c.read_exact(&mut got).unwrap();
        assert_eq!(&got, b"efgh");
    }
}
