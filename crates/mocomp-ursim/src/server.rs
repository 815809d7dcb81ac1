//! The simulator's sockets and threads.

use crate::controller::{Controller, ControllerConfig, InputSlot, OutputVar};
use mocomp_ur::codec::{
    FrameDecoder, PROTOCOL_V2, Recipe, Reply, Request, TextMessage, decode_request, encode_reply,
};
use mocomp_ur::line::{LineRead, read_line_bounded};
use mocomp_ur::types::{DataType, Value};
use std::collections::HashMap;
use std::io::{BufReader, ErrorKind, Read, Write};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

/// Ports to serve (0: any free port, for tests that do not need the standard ones).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Ports {
    /// RTDE (30004).
    pub rtde: u16,
    /// Dashboard (29999).
    pub dashboard: u16,
    /// Primary (30001).
    pub primary: u16,
    /// Secondary (30002).
    pub secondary: u16,
    /// Real-time (30003).
    pub realtime: u16,
}

impl Ports {
    /// The standard UR ports.
    pub const STANDARD: Ports = Ports {
        rtde: 30004,
        dashboard: 29999,
        primary: 30001,
        secondary: 30002,
        realtime: 30003,
    };
    /// Any free ports.
    pub const EPHEMERAL: Ports = Ports {
        rtde: 0,
        dashboard: 0,
        primary: 0,
        secondary: 0,
        realtime: 0,
    };
}

/// Who steps the controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimClock {
    /// A thread, every controller period on the machine's monotonic clock.
    RealTime,
    /// The owner, through [`Sim::step`].
    Stepped,
}

/// Simulator settings.
#[derive(Debug, Clone)]
pub struct SimConfig {
    /// The controller.
    pub controller: ControllerConfig,
    /// Address to serve on (a loopback address per robot).
    pub host: IpAddr,
    /// Ports.
    pub ports: Ports,
    /// Clock.
    pub clock: SimClock,
    /// Highest RTDE protocol version accepted (2; 1 to emulate an old controller).
    pub max_protocol: u16,
}

impl SimConfig {
    /// A real-time simulator of `controller` on the standard ports of `host`.
    pub fn new(controller: ControllerConfig, host: IpAddr) -> Self {
        Self {
            controller,
            host,
            ports: Ports::STANDARD,
            clock: SimClock::RealTime,
            max_protocol: PROTOCOL_V2,
        }
    }

    /// A stepped simulator on free ports of 127.0.0.1 (for tests).
    pub fn stepped_local(controller: ControllerConfig) -> Self {
        Self {
            controller,
            host: IpAddr::V4(Ipv4Addr::LOCALHOST),
            ports: Ports::EPHEMERAL,
            clock: SimClock::Stepped,
            max_protocol: PROTOCOL_V2,
        }
    }
}

/// The simulator could not start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A port could not be bound.
    #[error("cannot serve {what} on {addr}: {source}")]
    Bind {
        /// Which interface.
        what: &'static str,
        /// The address.
        addr: SocketAddr,
        /// The cause.
        source: std::io::Error,
    },
    /// A thread could not be started.
    #[error("cannot start the {0} thread")]
    Thread(&'static str),
}

/// The addresses served.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SimAddrs {
    /// RTDE.
    pub rtde: SocketAddr,
    /// Dashboard.
    pub dashboard: SocketAddr,
    /// Primary.
    pub primary: SocketAddr,
    /// Secondary.
    pub secondary: SocketAddr,
    /// Real-time.
    pub realtime: SocketAddr,
}

/// Counters.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Controller cycles run.
    pub ticks: u64,
    /// RTDE input data packages applied.
    pub inputs: u64,
    /// RTDE output data packages sent.
    pub outputs: u64,
    /// Output packages skipped because a client did not read fast enough.
    pub outputs_skipped: u64,
    /// Malformed or unknown RTDE packages received.
    pub bad_packages: u64,
    /// Real-time wake-ups that came a period or more late (the cycles missed were made up, up
    /// to 25 ms of them).
    pub overruns: u64,
    /// Cycles its clock gave up, more than 25 ms late (a stopped process): never run, never
    /// sent. A real controller gives up none; a client can answer none of them.
    pub cycles_given_up: u64,
    /// Cycles at which the RTDE watchdog would have stopped the program while the client's
    /// packages waited unread on the simulator's socket (its own reader late, not the client
    /// silent), so it did not.
    pub watchdog_deferred: u64,
}

struct OutSetup {
    recipe: Recipe,
    vars: Vec<OutputVar>,
    divider: u64,
}

struct Conn {
    id: u64,
    version: u16,
    out: Option<OutSetup>,
    started: bool,
    tx: SyncSender<Vec<u8>>,
    /// The connection's socket, to see whether its packages wait unread
    /// ([`input_waiting`]).
    socket: Option<TcpStream>,
}

#[derive(Default)]
struct Counters {
    inputs: AtomicU64,
    outputs: AtomicU64,
    skipped: AtomicU64,
    bad: AtomicU64,
    overruns: AtomicU64,
    given_up: AtomicU64,
    watchdog_deferred: AtomicU64,
}

struct Shared {
    ctrl: Mutex<Controller>,
    conns: Mutex<Vec<Conn>>,
    owners: Mutex<HashMap<InputSlot, u64>>,
    stop: AtomicBool,
    next_id: AtomicU64,
    counters: Counters,
    max_protocol: u16,
    rate_hz: f64,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A panic in another simulator thread must not take the simulator down with it.
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The controller of a [`Sim`], for another thread ([`Sim::handle`]).
#[derive(Clone)]
pub struct SimHandle(Arc<Shared>);

impl std::fmt::Debug for SimHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimHandle").finish_non_exhaustive()
    }
}

impl SimHandle {
    /// Runs `f` on the controller.
    pub fn with<R>(&self, f: impl FnOnce(&mut Controller) -> R) -> R {
        f(&mut lock(&self.0.ctrl))
    }
}

/// A running simulated controller. Dropping it stops every thread and closes every socket.
pub struct Sim {
    shared: Arc<Shared>,
    threads: Vec<JoinHandle<()>>,
    addrs: SimAddrs,
    clock: SimClock,
}

impl std::fmt::Debug for Sim {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Sim")
            .field("addrs", &self.addrs)
            .field("clock", &self.clock)
            .finish()
    }
}

impl Sim {
    /// Binds the ports and starts serving.
    pub fn start(config: SimConfig) -> Result<Sim, SimError> {
        let bind = |what: &'static str, port: u16| {
            let addr = SocketAddr::new(config.host, port);
            let l =
                TcpListener::bind(addr).map_err(|source| SimError::Bind { what, addr, source })?;
            l.set_nonblocking(true)
                .map_err(|source| SimError::Bind { what, addr, source })?;
            let local = l
                .local_addr()
                .map_err(|source| SimError::Bind { what, addr, source })?;
            Ok::<_, SimError>((l, local))
        };
        let (rtde, rtde_addr) = bind("RTDE", config.ports.rtde)?;
        let (dash, dash_addr) = bind("the dashboard", config.ports.dashboard)?;
        let (prim, prim_addr) = bind("the primary interface", config.ports.primary)?;
        let (sec, sec_addr) = bind("the secondary interface", config.ports.secondary)?;
        let (rt, rt_addr) = bind("the real-time interface", config.ports.realtime)?;
        let ctrl = Controller::new(config.controller.clone());
        let rate_hz = 1.0 / ctrl.period_s();
        let shared = Arc::new(Shared {
            ctrl: Mutex::new(ctrl),
            conns: Mutex::new(Vec::new()),
            owners: Mutex::new(HashMap::new()),
            stop: AtomicBool::new(false),
            next_id: AtomicU64::new(1),
            counters: Counters::default(),
            max_protocol: config.max_protocol.clamp(1, PROTOCOL_V2),
            rate_hz,
        });
        let mut sim = Sim {
            shared: Arc::clone(&shared),
            threads: Vec::new(),
            addrs: SimAddrs {
                rtde: rtde_addr,
                dashboard: dash_addr,
                primary: prim_addr,
                secondary: sec_addr,
                realtime: rt_addr,
            },
            clock: config.clock,
        };
        sim.spawn("ursim-rtde", {
            let s = Arc::clone(&shared);
            move || accept_loop(rtde, s, serve_rtde)
        })?;
        sim.spawn("ursim-dashboard", {
            let s = Arc::clone(&shared);
            move || accept_loop(dash, s, serve_dashboard)
        })?;
        for (name, l) in [
            ("ursim-primary", prim),
            ("ursim-secondary", sec),
            ("ursim-realtime", rt),
        ] {
            sim.spawn(name, {
                let s = Arc::clone(&shared);
                move || accept_loop(l, s, serve_script)
            })?;
        }
        if config.clock == SimClock::RealTime {
            sim.spawn("ursim-tick", {
                let s = Arc::clone(&shared);
                move || tick_loop(s)
            })?;
        }
        Ok(sim)
    }

    fn spawn(
        &mut self,
        name: &'static str,
        f: impl FnOnce() + Send + 'static,
    ) -> Result<(), SimError> {
        let h = std::thread::Builder::new()
            .name(name.into())
            .spawn(f)
            .map_err(|_| SimError::Thread(name))?;
        self.threads.push(h);
        Ok(())
    }

    /// The addresses served.
    pub fn addrs(&self) -> SimAddrs {
        self.addrs
    }

    /// A client configuration for this simulator's addresses and ports (whatever they are).
    pub fn ur_config(&self) -> mocomp_ur::UrConfig {
        let a = self.addrs;
        let mut c = mocomp_ur::UrConfig::new(a.rtde.ip());
        c.rtde_port = a.rtde.port();
        c.dashboard_port = a.dashboard.port();
        c.script_port = a.realtime.port();
        c
    }

    /// Runs one controller cycle and sends the outputs due (stepped clock; with the real-time
    /// clock this adds a cycle).
    pub fn step(&self) {
        tick(&self.shared);
    }

    /// Runs `f` while a background thread steps this (stepped) simulator at most at real time,
    /// one cycle per controller period: a client that connects needs state packages, and its
    /// program's watchdog must judge the client's silence over time that really passed (a
    /// simulator stepped faster than real time would stop a client that a busy machine delayed
    /// for a few milliseconds).
    pub fn stepping_in_real_time<T>(&self, f: impl FnOnce() -> T) -> T {
        let done = AtomicBool::new(false);
        let period = Duration::from_secs_f64(1.0 / self.shared.rate_hz);
        std::thread::scope(|s| {
            s.spawn(|| {
                while !done.load(Ordering::Relaxed) {
                    self.step();
                    std::thread::sleep(period);
                }
            });
            let r = f();
            done.store(true, Ordering::Relaxed);
            r
        })
    }

    /// Runs `n` cycles.
    pub fn step_n(&self, n: usize) {
        for _ in 0..n {
            tick(&self.shared);
        }
    }

    /// Runs `f` on the controller (inspect it, press the emergency stop, …).
    pub fn with<R>(&self, f: impl FnOnce(&mut Controller) -> R) -> R {
        f(&mut lock(&self.shared.ctrl))
    }

    /// A handle to the controller another thread can keep (the cell's events from a person in
    /// the room); it does not keep the simulator running.
    pub fn handle(&self) -> SimHandle {
        SimHandle(Arc::clone(&self.shared))
    }

    /// Counters.
    pub fn stats(&self) -> SimStats {
        let c = &self.shared.counters;
        SimStats {
            ticks: lock(&self.shared.ctrl).ticks(),
            inputs: c.inputs.load(Ordering::Relaxed),
            outputs: c.outputs.load(Ordering::Relaxed),
            outputs_skipped: c.skipped.load(Ordering::Relaxed),
            bad_packages: c.bad.load(Ordering::Relaxed),
            overruns: c.overruns.load(Ordering::Relaxed),
            cycles_given_up: c.given_up.load(Ordering::Relaxed),
            watchdog_deferred: c.watchdog_deferred.load(Ordering::Relaxed),
        }
    }

    /// RTDE connections open now.
    pub fn rtde_connections(&self) -> usize {
        lock(&self.shared.conns).len()
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            t.join().ok();
        }
    }
}

fn tick(shared: &Shared) {
    let mut ctrl = lock(&shared.ctrl);
    let mut conns = lock(&shared.conns);
    // Asked only when the watchdog is about to fire: a syscall per connection.
    if ctrl.watchdog_due() && conns.iter().any(input_waiting) {
        ctrl.note_unread_input();
        shared
            .counters
            .watchdog_deferred
            .fetch_add(1, Ordering::Relaxed);
    }
    ctrl.step();
    let t = ctrl.ticks();
    let mut values = Vec::new();
    for c in conns.iter_mut() {
        let Some(o) = c.out.as_ref().filter(|_| c.started) else {
            continue;
        };
        if !t.is_multiple_of(o.divider) {
            continue;
        }
        values.clear();
        values.extend(o.vars.iter().map(|v| ctrl.output(*v)));
        let mut bytes = Vec::with_capacity(o.recipe.size() + 4);
        if o.recipe
            .encode_output_package(&values, c.version, &mut bytes)
            .is_err()
        {
            continue;
        }
        match c.tx.try_send(bytes) {
            Ok(()) => shared.counters.outputs.fetch_add(1, Ordering::Relaxed),
            Err(_) => shared.counters.skipped.fetch_add(1, Ordering::Relaxed),
        };
    }
}

/// Longest stretch of missed cycles the real-time clock makes up, s. A real controller never
/// falls behind; a simulator on a busy PC can, and making the cycles up keeps its time on the wall
/// clock (a client's late command is then judged over the real time that passed, as on a robot).
/// Beyond this (a stopped process) it restarts from now instead of bursting, below the 50 ms
/// watchdog so a burst never looks like a silent client.
const CATCH_UP_S: f64 = 0.025;

fn tick_loop(shared: Arc<Shared>) {
    let period = Duration::from_secs_f64(1.0 / shared.rate_hz);
    let max_late = ((CATCH_UP_S * shared.rate_hz).ceil() as u32).max(1);
    let mut ticker = mocomp_rt::Ticker::new(period, max_late);
    while !shared.stop.load(Ordering::Relaxed) {
        let due = ticker.wait();
        if due > 1 {
            shared.counters.overruns.fetch_add(1, Ordering::Relaxed);
        }
        shared
            .counters
            .given_up
            .store(ticker.missed(), Ordering::Relaxed);
        for _ in 0..due {
            tick(&shared);
        }
    }
}

fn accept_loop(l: TcpListener, shared: Arc<Shared>, serve: fn(TcpStream, Arc<Shared>)) {
    let mut workers: Vec<JoinHandle<()>> = Vec::new();
    while !shared.stop.load(Ordering::Relaxed) {
        match l.accept() {
            Ok((s, _)) => {
                if s.set_nonblocking(false).is_err() {
                    continue;
                }
                s.set_nodelay(true).ok();
                s.set_read_timeout(Some(Duration::from_millis(50))).ok();
                let sh = Arc::clone(&shared);
                if let Ok(h) = std::thread::Builder::new()
                    .name("ursim-conn".into())
                    .spawn(move || serve(s, sh))
                {
                    workers.push(h);
                }
                workers.retain(|h| !h.is_finished());
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
    }
    for h in workers {
        h.join().ok();
    }
}

/// Whether bytes the client sent wait unread on `c`'s socket. The simulator's reader is a
/// thread the host may leave unscheduled for tens of milliseconds on a busy machine while the
/// cycle's thread runs on another CPU; a real controller reads its inputs every cycle.
fn input_waiting(c: &Conn) -> bool {
    use nix::sys::socket::{MsgFlags, recv};
    use std::os::fd::AsRawFd;
    let Some(s) = c.socket.as_ref() else {
        return false;
    };
    let mut byte = [0u8; 1];
    // Peeked, not taken, and without blocking: the reader takes the bytes when it runs.
    matches!(
        recv(
            s.as_raw_fd(),
            &mut byte,
            MsgFlags::MSG_PEEK | MsgFlags::MSG_DONTWAIT
        ),
        Ok(n) if n > 0
    )
}

/// Reads what is available; `None` when the connection ended or the simulator stops.
fn read_some(s: &mut TcpStream, buf: &mut [u8], shared: &Shared) -> Option<usize> {
    loop {
        if shared.stop.load(Ordering::Relaxed) {
            return None;
        }
        match s.read(buf) {
            Ok(0) => return None,
            Ok(n) => return Some(n),
            Err(e)
                if matches!(
                    e.kind(),
                    ErrorKind::WouldBlock | ErrorKind::TimedOut | ErrorKind::Interrupted
                ) => {}
            Err(_) => return None,
        }
    }
}

fn writer_loop(mut s: TcpStream, rx: Receiver<Vec<u8>>) {
    while let Ok(b) = rx.recv() {
        if s.write_all(&b).is_err() {
            break;
        }
    }
    s.shutdown(std::net::Shutdown::Both).ok();
}

struct RtdeSession {
    id: u64,
    version: u16,
    inputs: HashMap<u8, (Recipe, Vec<InputSlot>)>,
    next_input_id: u8,
    next_output_id: u8,
    warnings: u32,
    tx: SyncSender<Vec<u8>>,
    values: Vec<Value>,
}

impl RtdeSession {
    fn reply(&self, r: &Reply<'_>) {
        let mut b = Vec::new();
        if encode_reply(r, self.version, &mut b).is_ok() {
            self.tx.send(b).ok();
        }
    }

    fn warn(&mut self, shared: &Shared, text: String) {
        shared.counters.bad.fetch_add(1, Ordering::Relaxed);
        lock(&shared.ctrl).record_event(format!("RTDE client {}: {text}", self.id));
        if self.warnings < 10 && self.version >= PROTOCOL_V2 {
            self.warnings += 1;
            let mut message = text;
            message.truncate(250);
            self.reply(&Reply::Text(TextMessage {
                level: 2,
                message,
                source: "ursim".into(),
            }));
        }
    }
}

fn serve_rtde(mut s: TcpStream, shared: Arc<Shared>) {
    let Ok(ws) = s.try_clone() else { return };
    let (tx, rx) = sync_channel::<Vec<u8>>(64);
    let writer = std::thread::Builder::new()
        .name("ursim-rtde-writer".into())
        .spawn(move || writer_loop(ws, rx));
    let id = shared.next_id.fetch_add(1, Ordering::Relaxed);
    lock(&shared.conns).push(Conn {
        id,
        version: 1,
        out: None,
        started: false,
        tx: tx.clone(),
        socket: s.try_clone().ok(),
    });
    let mut sess = RtdeSession {
        id,
        version: 1,
        inputs: HashMap::new(),
        next_input_id: 1,
        next_output_id: 1,
        warnings: 0,
        tx,
        values: Vec::new(),
    };
    let mut dec = FrameDecoder::new();
    let mut buf = [0u8; 8192];
    'conn: while let Some(n) = read_some(&mut s, &mut buf, &shared) {
        dec.push(&buf[..n]);
        loop {
            let frame = match dec.next_frame() {
                Ok(Some(f)) => f,
                Ok(None) => break,
                Err(e) => {
                    sess.warn(&shared, format!("{e}; closing the connection"));
                    break 'conn;
                }
            };
            let (kind, offset) = (frame.kind, frame.offset);
            match decode_request(frame.kind, frame.payload, sess.version) {
                Ok(req) => handle_request(req, &mut sess, &shared),
                Err(e) => {
                    sess.warn(&shared, format!("package at byte {offset}: {e}"));
                    // A request that expects a reply gets a refusal, so clients do not hang.
                    match kind {
                        b'V' => sess.reply(&Reply::ProtocolVersion(false)),
                        b'S' => sess.reply(&Reply::Start(false)),
                        b'P' => sess.reply(&Reply::Pause(false)),
                        _ => {}
                    }
                }
            }
        }
    }
    // Disconnected: forget the connection and release its inputs.
    lock(&shared.conns).retain(|c| c.id != id);
    lock(&shared.owners).retain(|_, owner| *owner != id);
    drop(sess);
    s.shutdown(std::net::Shutdown::Both).ok();
    if let Ok(w) = writer {
        w.join().ok();
    }
}

fn with_conn(shared: &Shared, id: u64, f: impl FnOnce(&mut Conn)) {
    if let Some(c) = lock(&shared.conns).iter_mut().find(|c| c.id == id) {
        f(c);
    }
}

fn handle_request(req: Request<'_>, sess: &mut RtdeSession, shared: &Shared) {
    match req {
        Request::ProtocolVersion(v) => {
            let ok = (1..=shared.max_protocol).contains(&v);
            // The reply goes out in the version in force before the change.
            sess.reply(&Reply::ProtocolVersion(ok));
            if ok {
                sess.version = v;
                with_conn(shared, sess.id, |c| c.version = v);
            }
        }
        Request::ControllerVersion => {
            let v = lock(&shared.ctrl).config().version();
            sess.reply(&Reply::ControllerVersion(v));
        }
        Request::Text(t) => {
            lock(&shared.ctrl).record_event(format!(
                "RTDE client {} says ({}): {}",
                sess.id, t.source, t.message
            ));
        }
        Request::SetupOutputs { frequency, names } => {
            setup_outputs(frequency, &names, sess, shared);
        }
        Request::SetupInputs { names } => setup_inputs(&names, sess, shared),
        Request::Start => {
            let mut has_outputs = false;
            with_conn(shared, sess.id, |c| has_outputs = c.out.is_some());
            sess.reply(&Reply::Start(has_outputs));
            if has_outputs {
                with_conn(shared, sess.id, |c| c.started = true);
            }
        }
        Request::Pause => {
            with_conn(shared, sess.id, |c| c.started = false);
            sess.reply(&Reply::Pause(true));
        }
        Request::Data { recipe_id, payload } => data(recipe_id, payload, sess, shared),
    }
}

/// SETUP_OUTPUTS: the recipe, each name resolved (or `NOT_FOUND`), at the frequency asked for
/// (the controller's rate at most).
fn setup_outputs(
    frequency: Option<f64>,
    names: &[String],
    sess: &mut RtdeSession,
    shared: &Shared,
) {
    let resolved: Vec<Option<(OutputVar, DataType)>> =
        names.iter().map(|n| OutputVar::resolve(n)).collect();
    let types: Vec<String> = resolved
        .iter()
        .map(|r| r.map_or("NOT_FOUND".to_string(), |(_, t)| t.name().to_string()))
        .collect();
    let id = sess.next_output_id;
    let ok = !names.is_empty() && resolved.iter().all(Option::is_some);
    if ok {
        sess.next_output_id = sess.next_output_id.wrapping_add(1).max(1);
        let rate = shared.rate_hz;
        let f = frequency
            .filter(|f| f.is_finite() && *f > 0.0)
            .unwrap_or(rate);
        let divider = (rate / f.min(rate)).round().max(1.0) as u64;
        let vars: Vec<OutputVar> = resolved.iter().flatten().map(|(v, _)| *v).collect();
        let dtypes: Vec<DataType> = resolved.iter().flatten().map(|(_, t)| *t).collect();
        let recipe = Recipe::new(id, names.to_vec(), dtypes);
        with_conn(shared, sess.id, |c| {
            c.out = Some(OutSetup {
                recipe,
                vars,
                divider,
            });
        });
    }
    sess.reply(&Reply::SetupOutputs {
        recipe_id: Some(if ok { id } else { 0 }),
        types,
    });
}

/// SETUP_INPUTS: each name resolved, refused when another client owns it (`IN_USE`).
fn setup_inputs(names: &[String], sess: &mut RtdeSession, shared: &Shared) {
    let mut owners = lock(&shared.owners);
    let mut types = Vec::with_capacity(names.len());
    let mut slots = Vec::with_capacity(names.len());
    let mut dtypes = Vec::with_capacity(names.len());
    let mut ok = !names.is_empty();
    for n in names {
        match InputSlot::resolve(n) {
            None => {
                ok = false;
                types.push("NOT_FOUND".to_string());
            }
            Some((slot, t)) => match owners.get(&slot) {
                Some(owner) if *owner != sess.id => {
                    ok = false;
                    types.push("IN_USE".to_string());
                }
                _ => {
                    types.push(t.name().to_string());
                    slots.push(slot);
                    dtypes.push(t);
                }
            },
        }
    }
    let id = if ok && sess.next_input_id < u8::MAX {
        let id = sess.next_input_id;
        sess.next_input_id += 1;
        for s in &slots {
            owners.insert(*s, sess.id);
        }
        sess.inputs
            .insert(id, (Recipe::new(id, names.to_vec(), dtypes), slots));
        id
    } else {
        0
    };
    drop(owners);
    sess.reply(&Reply::SetupInputs {
        recipe_id: id,
        types,
    });
}

/// A data package: its inputs applied to the controller, or a warning naming what was wrong.
fn data(recipe_id: u8, payload: &[u8], sess: &mut RtdeSession, shared: &Shared) {
    let Some((recipe, slots)) = sess.inputs.get(&recipe_id) else {
        let msg = format!("data package for unknown input recipe {recipe_id}");
        sess.warn(shared, msg);
        return;
    };
    let mut values = std::mem::take(&mut sess.values);
    match recipe.unpack(payload, &mut values) {
        Ok(()) => {
            let mut ctrl = lock(&shared.ctrl);
            for (slot, v) in slots.iter().zip(&values) {
                ctrl.apply_input(*slot, *v);
            }
            ctrl.finish_inputs();
            drop(ctrl);
            shared.counters.inputs.fetch_add(1, Ordering::Relaxed);
        }
        Err(e) => {
            let msg = e.to_string();
            sess.warn(shared, msg);
        }
    }
    sess.values = values;
}

/// Reads `\n`-terminated lines (lossy UTF-8) until the peer closes, the simulator stops, or
/// `on_line` returns false. A line longer than `max` is dropped and reported.
fn for_each_line(
    s: TcpStream,
    shared: &Shared,
    max: usize,
    mut on_line: impl FnMut(String) -> bool,
) {
    let mut r = BufReader::new(s);
    let mut line = Vec::new();
    while !shared.stop.load(Ordering::Relaxed) {
        match read_line_bounded(&mut r, max, &mut line) {
            Ok(LineRead::Complete) => {
                let text = String::from_utf8_lossy(&line).into_owned();
                line.clear();
                if !on_line(text) {
                    return;
                }
            }
            Ok(LineRead::Partial) => {}
            Ok(LineRead::TooLong) => {
                // Skipped to its end: what follows the next \n is a line again.
                line.clear();
                lock(&shared.ctrl).record_event(format!("input line over {max} bytes dropped"));
                loop {
                    match read_line_bounded(&mut r, max, &mut line) {
                        Ok(LineRead::TooLong) | Ok(LineRead::Partial) => line.clear(),
                        Ok(LineRead::Complete) => break,
                        Ok(LineRead::Closed) | Err(_) => return,
                    }
                    if shared.stop.load(Ordering::Relaxed) {
                        return;
                    }
                }
                line.clear();
            }
            Ok(LineRead::Closed) | Err(_) => return,
        }
    }
}

fn serve_dashboard(s: TcpStream, shared: Arc<Shared>) {
    let Ok(mut w) = s.try_clone() else { return };
    if w.write_all(b"Connected: Universal Robots Dashboard Server\n")
        .is_err()
    {
        return;
    }
    for_each_line(s, &shared, 4096, |text| {
        let reply = lock(&shared.ctrl).dashboard(&text);
        w.write_all(format!("{reply}\n").as_bytes()).is_ok() && reply != "Disconnected"
    });
}

/// Largest program accepted on a script port.
const MAX_PROGRAM: usize = 4 << 20;

fn serve_script(s: TcpStream, shared: Arc<Shared>) {
    let mut program: Option<String> = None;
    for_each_line(s, &shared, MAX_PROGRAM, |text| {
        let starts_block = text.starts_with("def ") || text.starts_with("sec ");
        match program.as_mut() {
            None if starts_block => program = Some(text),
            None => {
                if !text.trim().is_empty() {
                    lock(&shared.ctrl).record_event(format!(
                        "script line outside a program ignored: {:?}",
                        text.trim().chars().take(60).collect::<String>()
                    ));
                }
            }
            Some(p) => {
                p.push_str(&text);
                if text.trim_end() == "end" {
                    if let Some(p) = program.take() {
                        lock(&shared.ctrl).load_program(&p);
                    }
                } else if p.len() > MAX_PROGRAM {
                    program = None;
                    lock(&shared.ctrl).record_event("program over 4 MiB discarded".into());
                }
            }
        }
        true
    });
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

    use super::*;
    use std::io::Write;
    use std::net::TcpListener;
    use std::time::Instant;

    #[test]
    fn input_waiting_sees_bytes_the_reader_has_not_taken_and_takes_none() {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let mut client = TcpStream::connect(l.local_addr().unwrap()).unwrap();
        let (mut server, _) = l.accept().unwrap();
        let (tx, _rx) = sync_channel(1);
        let conn = Conn {
            id: 0,
            version: 2,
            out: None,
            started: false,
            tx,
            socket: server.try_clone().ok(),
        };
        assert!(!input_waiting(&conn));
        client.write_all(b"abc").unwrap();
        let t = Instant::now();
        while !input_waiting(&conn) {
            assert!(t.elapsed() < Duration::from_secs(5), "never seen");
            std::thread::sleep(Duration::from_millis(1));
        }
        // Peeked only: the reader still gets every byte.
        assert!(input_waiting(&conn));
        let mut got = [0u8; 3];
        server.read_exact(&mut got).unwrap();
        assert_eq!(&got, b"abc");
        assert!(!input_waiting(&conn));
        // A closed peer is no input.
        drop(client);
        assert!(!input_waiting(&conn));
        let without = Conn {
            socket: None,
            ..conn
        };
        assert!(!input_waiting(&without));
    }
}
