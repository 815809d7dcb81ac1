#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! The faults of a real cell (issue 29), injected while `mocomp run` compensates against a
//! controller in another process: `mocomp ursim` started on its own, reached through the test
//! kit's fault-injecting relay (RTDE, dashboard and script ports on an address of the relay's
//! own), the operator at the console. A monitor that is not mocomp (ur_rtde's receive
//! interface) reads the controller's own RTDE stream directly, beside the loop's connection,
//! and says when the arm stood still.
//!
//! For each fault: the loop's named event; the arm still (and how soon); a fault the controller
//! reports, or a gap long enough that it stopped the arm itself, stays until the operator
//! resumes, and then the loop comes back from where the arm is, by a path (never a silent jump
//! back); every cycle is in the log, and (across a lost and remade connection) in the MCAP
//! recording.

mod common;
use common::example_changed;
use common::on_goal::OnGoal;
use common::session::Session;
use mocomp_testkit::controller::ChildController;
use mocomp_testkit::proxy::{Direction, FaultProxy};
use mocomp_testkit::{PythonPeer, TempDir, monotonic_s};
use mocomp_ur::dashboard::Dashboard;
use serde_json::{Value, json};
use std::net::SocketAddr;
use std::path::Path;
use std::sync::Mutex;
use std::time::Duration;

/// One cell at a time in this file: a loop and a controller at real-time priority each, on two
/// cores.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The controller's own view of the arm, read by a third party (ur_rtde's receive interface,
/// SDU's client) over a connection of its own beside the loop's: when each new state came
/// (CLOCK_MONOTONIC) and the fastest joint's speed.
struct Monitor(Mutex<PythonPeer>);

impl Monitor {
    fn start(controller: SocketAddr) -> Self {
        let mut peer = PythonPeer::start("ur_rtde_peer.py", "ur-rtde", "1.6.5");
        peer.request(&json!({"op": "watch", "host": controller.ip().to_string()}));
        Self(Mutex::new(peer))
    }

    fn ask(&self, req: &Value) -> Value {
        self.0.lock().unwrap().request(req)
    }

    /// The fastest joint's top speed in [from, to) (monotonic s), rad/s.
    fn top_speed(&self, from: f64, to: f64) -> f64 {
        self.ask(&json!({"op": "top_speed", "from": from, "to": to}))["speed"]
            .as_f64()
            .unwrap_or(0.0)
    }

    /// How long after `t0` (monotonic s) the arm came to stand (every joint below 1 mrad/s)
    /// and stayed there for `stay`; `None` if it never did.
    fn still_after(&self, t0: f64, stay: Duration) -> Option<Duration> {
        // What the monitor has read so far may not reach that far yet on a busy machine: asked
        // again until it does (the deadline only catches an arm that never stands).
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        loop {
            let answer =
                self.ask(&json!({"op": "still_after", "t0": t0, "stay_s": stay.as_secs_f64()}));
            let still = answer["still_s"].as_f64().map(Duration::from_secs_f64);
            if still.is_some() || std::time::Instant::now() >= deadline {
                // The controller's clock behind the wall clock by this (its given-up cycles),
                // which the monitor's placing of each state on the wall clock follows.
                eprintln!("the monitor: {answer}");
                return still;
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// A controller behind the relay, the monitor on it, and the loop with its console.
struct Cell {
    controller: ChildController,
    rtde: FaultProxy,
    /// The tracker's relay, when the test put one between the loop and the tracker server.
    igtl: Option<FaultProxy>,
    _others: [FaultProxy; 2],
    monitor: Monitor,
    session: Session,
    /// The MCAP recording, if the test asked for one.
    recorded: Option<String>,
    dir: TempDir,
    /// What the test did as the operator, and the stops it did not cause.
    operator: std::cell::RefCell<Operator>,
}

/// The operator's side of a cell: the resumes posted, whether a fault the test injected still
/// waits for its resume, and the stops nobody injected.
///
/// Those happen: the simulated controller and the loop share this machine, and a virtual
/// machine's host can stop one of its virtual CPUs for 100 ms (seen with `perf sched` under
/// `stress-ng --cpu 2`: one CPU without a context switch for 100.5 ms while real-time threads
/// woken onto it waited, `/proc/stat` counting steal time). The program's 50 ms watchdog then
/// stops the arm, as a real controller would if the PC froze. A test does what an operator
/// does: it sees the loop faulted for that named reason, checks the controller says why, and
/// resumes; its counts of re-arms allow for them, and each is printed.
#[derive(Debug, Default)]
struct Operator {
    resumes: usize,
    injected: bool,
    unplanned: Vec<String>,
}

/// Starts `mocomp ursim` on `controller_ip` (behind the head), the relay on `relay_ip` (RTDE,
/// dashboard, script ports), and `mocomp run` against the relay for at most `seconds`, with its
/// CSV log.
fn cell(controller_ip: &str, relay_ip: &str, seconds: u32, seed: u64) -> Cell {
    cell_with(controller_ip, relay_ip, seconds, seed, &Extras::default())
}

/// What a test adds to [`cell`].
#[derive(Default)]
struct Extras<'a> {
    /// The simulated tracker's address and its relay's: the tracker's OpenIGTLink stream
    /// through a relay too.
    tracker: Option<(&'a str, &'a str)>,
    /// More changes to the example's text.
    changes: &'a [(&'a str, &'a str)],
    /// Record the run as MCAP (`--record`); [`Cell::finish`] reads it back.
    record: bool,
}

/// [`cell`], with `extras`.
fn cell_with(
    controller_ip: &str,
    relay_ip: &str,
    seconds: u32,
    seed: u64,
    extras: &Extras<'_>,
) -> Cell {
    let tracker = extras.tracker;
    let dir = TempDir::new(&format!("mocomp-faults-{relay_ip}"));
    let controller = ChildController::start(
        Path::new(env!("CARGO_BIN_EXE_mocomp")),
        "ur3e",
        controller_ip,
        [0.0225, -2.5706, -0.8144, -1.3275, 1.5692, -1.5483],
        &["--realtime", "fifo:49"],
    );
    let at = |ip: &str, port: u16| SocketAddr::new(ip.parse().unwrap(), port);
    let rtde = FaultProxy::start(at(relay_ip, 30004), at(controller_ip, 30004), seed).unwrap();
    let others = [29999, 30003]
        .map(|p| FaultProxy::start(at(relay_ip, p), at(controller_ip, p), seed + 1).unwrap());
    let monitor = Monitor::start(at(controller_ip, 30004));
    let igtl = tracker.map(|(server, relay)| {
        FaultProxy::start(at(relay, 18944), at(server, 18944), seed + 2).unwrap()
    });
    let (serve, connect) = tracker.map_or((String::new(), String::new()), |(server, relay)| {
        (
            format!("\nserve = \"{server}:18944\""),
            format!("igtl = \"{relay}:18944\""),
        )
    });
    let marker = "flange_from_marker = [0.0, 0.06, 0.02, 3.1416, 0.0, 0.0]";
    let mut changes = vec![("simulate = true ", "simulate = false".to_string())];
    if tracker.is_some() {
        changes.push(("# igtl = \"127.0.0.1:18944\"", connect));
        changes.push((marker, format!("{marker}{serve}")));
    }
    changes.extend(extras.changes.iter().map(|(a, b)| (*a, (*b).to_string())));
    let changes: Vec<(&str, &str)> = changes.iter().map(|(a, b)| (*a, b.as_str())).collect();
    let config = example_changed(&dir, relay_ip, &changes);
    let (csv, secs, mcap) = (
        dir.path("run.csv"),
        seconds.to_string(),
        dir.path("run.mcap"),
    );
    let mut args = vec![
        "run",
        "--config",
        &config,
        "--seconds",
        &secs,
        "--quiet",
        "--json",
        "--log-csv",
        &csv,
        "--dashboard",
        "127.0.0.1:0",
    ];
    if extras.record {
        args.extend(["--record", mcap.as_str()]);
    }
    let session = Session::spawn_json(&args);
    Cell {
        controller,
        rtde,
        igtl,
        _others: others,
        monitor,
        session,
        recorded: extras.record.then_some(mcap),
        dir,
        operator: Default::default(),
    }
}

impl Cell {
    /// Waits until the loop has tracked for a second of its own time, resuming (as an operator
    /// would) after a stop nobody injected (see [`Operator`]).
    fn tracking(&self, what: &str) {
        let wait = || {
            let mut deadline = std::time::Instant::now() + Duration::from_secs(40);
            let mut since: Option<f64> = None;
            loop {
                let (_, v) = self.session.get("/api/status");
                let t = v["t"].as_f64().unwrap_or(0.0);
                match v["mode"].as_str() {
                    Some("tracking") => {
                        let from = *since.get_or_insert(t);
                        if t - from >= 1.0 {
                            return;
                        }
                    }
                    Some("faulted") if self.unplanned_stop(&v) => {
                        since = None;
                        deadline = std::time::Instant::now() + Duration::from_secs(40);
                    }
                    _ => since = None,
                }
                assert!(
                    std::time::Instant::now() < deadline,
                    "waiting for tracking {what}; last status {v}; events {}",
                    self.session.get("/api/events").1
                );
                std::thread::sleep(Duration::from_millis(20));
            }
        };
        if let Err(e) = std::panic::catch_unwind(std::panic::AssertUnwindSafe(wait)) {
            // What the controller saw is half the story.
            eprintln!("the controller's log:\n{}", self.controller.log());
            std::panic::resume_unwind(e);
        }
    }

    /// Waits (up to `seconds`, from the last stop nobody injected) until the status satisfies
    /// `f`; returns it. As in [`Self::tracking`], a stop nobody injected is resumed as an
    /// operator would: on this machine one can come at any time (a stalled virtual CPU starves
    /// the controller's watchdog), and the loop, faulted, would show nothing else until then.
    fn wait_for(&self, what: &str, seconds: u64, f: impl Fn(&Value) -> bool) -> Value {
        let mut deadline = std::time::Instant::now() + Duration::from_secs(seconds);
        loop {
            let (_, v) = self.session.get("/api/status");
            if f(&v) {
                return v;
            }
            if v["mode"] == "faulted" && self.unplanned_stop(&v) {
                deadline = std::time::Instant::now() + Duration::from_secs(seconds);
            }
            assert!(
                std::time::Instant::now() < deadline,
                "waiting for {what}; last status {v}; events {}",
                self.session.get("/api/events").1
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// The loop is faulted: when no injected fault waits for its resume and every resume has
    /// been acted on, the stop is one nobody injected. It is named, the controller's account of
    /// it printed, and the operator resumes. True when it was.
    fn unplanned_stop(&self, status: &Value) -> bool {
        let op = self.operator.borrow();
        if op.injected {
            return false;
        }
        let (_, ev) = self.session.get("/api/events");
        let events: &[Value] = ev.as_array().map_or(&[], Vec::as_slice);
        // The console's events: the session's re-arm notes by their words, the loop's holds by
        // their rule's code (their text is in words).
        let rearm = |e: &Value| e["text"].as_str().is_some_and(|t| t.starts_with("re-arm"));
        let acted = events.iter().filter(|e| rearm(e)).count();
        // A fault after the last recovery (a recovery that failed is no new stop).
        let last_rearm = events.iter().rposition(rearm);
        let last_fault = events.iter().rposition(|e| {
            e["kind"] == "hold"
                && e["reason"]
                    .as_str()
                    .is_some_and(|r| r.starts_with("Robot("))
        });
        // The controller stopped the arm (a stale state alone resumes by itself).
        let stopped = status["reason"]
            .as_str()
            .is_some_and(|r| r.starts_with("Robot("));
        if !stopped || acted < op.resumes || last_fault.is_none() || last_fault < last_rearm {
            return false;
        }
        drop(op);
        let reason = status["reason"].to_string();
        let stops: Vec<String> = self
            .controller
            .log()
            .lines()
            .filter(|l| l.contains("program stopped"))
            .map(str::to_string)
            .collect();
        eprintln!(
            "a stop nobody injected: faulted ({reason}); the controller's stops: {stops:?}; resuming"
        );
        self.operator.borrow_mut().unplanned.push(reason);
        self.resume();
        true
    }

    /// The operator's resume.
    fn resume(&self) {
        let (code, _) = self.session.post_auth("/api/resume", &json!({}));
        assert_eq!(code, 200);
        let mut op = self.operator.borrow_mut();
        op.resumes += 1;
        op.injected = false;
    }

    /// A fault the test injects now: the loop's fault is expected until the next resume.
    fn injecting(&self) {
        self.operator.borrow_mut().injected = true;
    }

    /// The stops nobody injected so far.
    fn unplanned(&self) -> usize {
        self.operator.borrow().unplanned.len()
    }

    /// Ends the run; its JSON summary. Checks what every run must show: no protective stop
    /// (the controller refused no setpoint), the arm at a standstill, every cycle logged.
    fn finish(self) -> Value {
        self.finish_with_protective_stops(0)
    }

    /// [`Self::finish`], with `n` protective stops the test caused itself.
    fn finish_with_protective_stops(self, n: usize) -> Value {
        self.finish_logged(n).0
    }

    /// [`Self::finish_with_protective_stops`], and how the coil kept to its goal while tracking
    /// (read from the run's log before its folder goes).
    fn finish_logged(self, n: usize) -> (Value, OnGoal) {
        let (code, _) = self.session.post_auth("/api/stop", &json!({}));
        assert_eq!(code, 200);
        let (ok, out) = self.session.finish();
        assert!(ok, "the run failed: {out}");
        let v: Value = serde_json::from_str(&out).unwrap();
        let stops = self.controller.protective_stops();
        let caused = stops
            .iter()
            .filter(|l| l.contains("protective stop: "))
            .count();
        assert!(
            caused == n && !stops.iter().any(|l| l.contains("C204A3")),
            "{stops:?}"
        );
        assert_eq!(v["protective_stops"], n, "{v}");
        assert_eq!(v["stop"]["outcome"], "standstill", "{v}");
        assert_eq!(v["log_records_dropped"], 0, "{v}");
        // The run's end is the program's: EXIT, not the watchdog after a silent client. The
        // controller says so once it has read the run's last bytes (it is another process).
        let last_stop = |log: &str| {
            let lines: Vec<&str> = log.lines().collect();
            let stopped = lines.iter().rposition(|l| l.contains("program stopped"));
            let started = lines.iter().rposition(|l| l.contains("program started"));
            match (stopped, started) {
                (Some(a), Some(b)) if a > b => Some(lines[a].to_string()),
                _ => None,
            }
        };
        mocomp_testkit::wait_until("the controller's program stopped", || {
            last_stop(&self.controller.log()).is_some()
        });
        let last = last_stop(&self.controller.log()).unwrap_or_default();
        if !last.contains("received EXIT") {
            // A client the operating system gave no real-time priority can be starved past the
            // 50 ms watchdog at any moment, its stop included: the controller then stopped the
            // arm itself, which is what the watchdog is for. With real time, never.
            assert!(
                last.contains("RTDE watchdog") && v["realtime_complete"] == false,
                "the run's end: {last} (real time: {}){}",
                v["realtime"],
                self.controller.log()
            );
            eprintln!(
                "the run ended on the controller's watchdog: {last}; its client ran without real \
                 time ({})",
                v["realtime"]
            );
        }
        eprintln!(
            "robot state stale holds: {}; missed cycles: {}",
            v["robot_stale_holds"], v["missed_cycles"]
        );
        let rows = csv::Reader::from_path(self.dir.path("run.csv"))
            .unwrap()
            .records()
            .count();
        assert_eq!(
            rows as u64,
            v["cycles"].as_u64().unwrap(),
            "every cycle logged"
        );
        if let Some(mcap) = &self.recorded {
            // Read back by the ROS 2 MCAP reader (PyPI `mcap-ros2-support`): every message
            // decoded, every cycle's record in it, across the faults.
            assert!(v["record"]["error"].is_null(), "{v}");
            let mut py = PythonPeer::start("mcap_peer.py", "mcap-ros2-support", "0.6.0");
            let r = py.request(&json!({"op": "read", "path": mcap}));
            eprintln!("recorded: {}", r["counts"]);
            assert_eq!(r["undecoded"], 0, "{}", r["counts"]);
            assert_eq!(r["counts"]["/mocomp/cycle"], v["cycles"], "{}", r["counts"]);
        }
        let on_goal = OnGoal::read(&self.dir.path("run.csv"), CAUGHT_UP_MM);
        (v, on_goal)
    }
}

/// The loop holds the arm for a stale tracker (not for anything else that holds it).
fn held_for_a_stale_tracker(status: &Value) -> bool {
    status["mode"] == "holding"
        && status["reason"]
            .as_str()
            .is_some_and(|r| r.starts_with("TrackerStale"))
}

/// Below this deviation (mm) a coil that resumed straight on its goal has caught up with it.
const CAUGHT_UP_MM: f64 = 1.0;

/// The loop's re-arms.
fn rearms(ev: &[String]) -> usize {
    ev.iter().filter(|e| *e == "Rearmed").count()
}

/// The faults the robot reported: each latched stop once until its re-arm (a stop is held
/// again after a stale state in between, on a loaded host, without being another stop).
fn robot_faults(ev: &[String]) -> usize {
    let mut latched = false;
    let mut n = 0;
    for e in ev {
        if e.starts_with("Hold(Robot(") && !latched {
            latched = true;
            n += 1;
        } else if e == "Rearmed" {
            latched = false;
        }
    }
    n
}

/// The events' names in order (`Hold(Robot(ProgramStopped))`, `Rearmed`, …).
fn events(v: &Value) -> Vec<String> {
    v["event_log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e[1].as_str().unwrap().to_string())
        .collect()
}

/// Injects `fault` once the loop tracks; the arm must stand within `still_within`, the loop
/// stay faulted (the arm still) until the operator resumes, and come back by a path after it.
/// Returns how long the arm took to stand.
fn latched_fault(
    c: &Cell,
    what: &str,
    still_within: Duration,
    fault: impl FnOnce(&Cell),
) -> Duration {
    latched_fault_then(c, what, still_within, fault, |_| {})
}

/// [`latched_fault`], with what the operator does at the cell (`operator`) before resuming.
fn latched_fault_then(
    c: &Cell,
    what: &str,
    still_within: Duration,
    fault: impl FnOnce(&Cell),
    operator: impl FnOnce(&Cell),
) -> Duration {
    c.tracking(&format!("before the {what}"));
    let t0 = monotonic_s();
    c.injecting();
    fault(c);
    let s = &c.session;
    let v = s.wait_status_for(&format!("faulted after the {what}"), 10, |v| {
        v["mode"] == "faulted"
    });
    eprintln!("{what}: {} ({})", v["mode"], v["reason"]);
    // Two seconds on: still faulted, the arm standing, whatever the robot's health.
    std::thread::sleep(Duration::from_secs(2));
    let (_, v) = s.get("/api/status");
    assert_eq!(
        v["mode"], "faulted",
        "{what}: moved again without the operator: {v}"
    );
    let still = c
        .monitor
        .still_after(t0, Duration::from_millis(500))
        .unwrap_or_else(|| panic!("{what}: the arm never stood still"));
    assert!(still <= still_within, "{what}: still only after {still:?}");
    let quiet_from = t0 + still.as_secs_f64();
    let top = c.monitor.top_speed(quiet_from, monotonic_s());
    assert!(
        top < 1e-3,
        "{what}: the arm moved while latched ({top} rad/s)"
    );
    eprintln!(
        "{what}: arm still {:.0} ms after the fault",
        still.as_secs_f64() * 1e3
    );
    operator(c);
    // The operator resumes: the robot's recovery, then back by a path.
    c.resume();
    c.tracking(&format!("after the {what}"));
    still
}

#[test]
fn rtde_stalls_of_100_and_500_ms_and_a_2_s_cut_stop_the_arm_and_wait_for_the_operator() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = cell("127.0.0.101", "127.0.0.102", 120, 29);
    // Past the program's 50 ms watchdog: the controller stops the arm itself.
    for ms in [100, 500] {
        latched_fault(
            &c,
            &format!("{ms} ms RTDE stall"),
            Duration::from_millis(400),
            |c| {
                c.rtde.stall(Duration::from_millis(ms));
            },
        );
    }
    latched_fault(&c, "2 s RTDE cut", Duration::from_millis(400), |c| {
        c.rtde.cut();
        std::thread::sleep(Duration::from_secs(2));
        c.rtde.restore();
    });
    let unplanned = c.unplanned();
    let v = c.finish();
    let ev = events(&v);
    assert_rearmed_each_time(&ev, 3, unplanned, "the control program running again");
}

/// `n` faults latched, each re-armed by the operator (`recovered`: the session's note of what
/// the recovery did), each followed by the loop's resume; and `unplanned` stops nobody injected,
/// re-armed alike.
fn assert_rearmed_each_time(ev: &[String], n: usize, unplanned: usize, recovered: &str) {
    let rearms: Vec<usize> = (0..ev.len()).filter(|&i| ev[i] == "Rearmed").collect();
    assert_eq!(rearms.len(), n + unplanned, "{ev:?}");
    let as_said = rearms
        .iter()
        .filter(|&&i| ev[i - 1] == format!("re-armed: {recovered}"))
        .count();
    assert!(as_said >= n, "the recovery before each re-arm: {ev:?}");
    for &i in &rearms {
        assert!(
            ev[i - 1].starts_with("re-armed: "),
            "the recovery before the re-arm: {ev:?}"
        );
        // Since the resume before it: the fault that latched.
        let since = ev[..i].iter().rposition(|e| e == "Resume").unwrap_or(0);
        assert!(
            ev[since..i].iter().any(|e| e.starts_with("Hold(Robot")),
            "a fault named before the re-arm: {ev:?}"
        );
        // Then the loop resumes, or (the host stalled the loop past the controller's watchdog
        // again before it could) a new stop is named, which the operator re-arms in turn.
        let next = ev.get(i + 1).map_or("", String::as_str);
        assert!(
            next == "Resume" || next.starts_with("Hold(Robot") && unplanned > 0,
            "after the re-arm: {next:?} in {ev:?}"
        );
    }
    let last = rearms.last().copied().unwrap_or(0);
    assert!(
        ev[last..].iter().any(|e| e == "Resume" || e == "Reached"),
        "the last re-arm brought the loop back: {ev:?}"
    );
}

#[test]
fn a_reset_rtde_connection_is_reconnected_on_the_operators_resume() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    // Recorded: the MCAP file keeps every cycle across the lost connections.
    let c = cell_with(
        "127.0.0.103",
        "127.0.0.104",
        90,
        129,
        &Extras {
            record: true,
            ..Extras::default()
        },
    );
    latched_fault(&c, "RTDE reset", Duration::from_millis(400), |c| {
        c.rtde.reset()
    });
    assert!(c.rtde.connections() >= 2, "reconnected");
    // Corrupted state packages: the decoder's checks refuse them, the link is dropped, the
    // arm stops; the operator's resume connects again.
    latched_fault(
        &c,
        "corrupted RTDE state",
        Duration::from_millis(400),
        |c| {
            c.rtde.corrupt(Direction::Downstream, 64);
        },
    );
    let unplanned = c.unplanned();
    let v = c.finish();
    let ev = events(&v);
    assert_rearmed_each_time(
        &ev,
        2,
        unplanned,
        "connected again, the control program running",
    );
}

#[test]
fn short_rtde_stalls_are_ridden_out_or_resumed_from_by_a_path_without_the_operator() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = cell("127.0.0.105", "127.0.0.106", 60, 229);
    c.tracking("before the short stalls");
    // 10 ms: inside robot_stale_s, tracking goes on.
    for _ in 0..5 {
        c.rtde.stall(Duration::from_millis(10));
        std::thread::sleep(Duration::from_millis(300));
    }
    // 40 ms: the loop stops the arm itself (RobotStale), the program still runs (below its
    // 50 ms watchdog), and it comes back by itself: by a path, or, where the head has not gone
    // far from the held coil, straight on its goal, catching up within the command's limits.
    for _ in 0..3 {
        c.rtde.stall(Duration::from_millis(40));
        c.tracking("after a 40 ms stall");
    }
    let unplanned = c.unplanned();
    let (v, on_goal) = c.finish_logged(0);
    let ev = events(&v);
    eprintln!("{ev:?}");
    assert_eq!(rearms(&ev), unplanned, "{ev:?}");
    assert!(
        ev.iter().filter(|e| *e == "Hold(RobotStale)").count() >= 3,
        "{ev:?}"
    );
    on_goal.check(5.0, 1.0, &v);
}

/// The controller's dashboard, reached directly (as the teach pendant acts on the controller,
/// not through mocomp's network).
fn pendant(ip: &str) -> Dashboard {
    Dashboard::connect(
        SocketAddr::new(ip.parse().unwrap(), 29999),
        Duration::from_secs(2),
    )
    .unwrap()
}

/// The operator at the pendant and the console after the arm was powered off: power on,
/// release the brakes, and wait until the loop sees the arm ready with only its program stopped
/// (on a busy machine the loop's state can lag the pendant: a resume before it sees the arm
/// running is refused, "robot mode IDLE", and would need another the test would not count).
fn power_on_and_release(c: &Cell, ip: &str) {
    let mut d = pendant(ip);
    d.power_on().unwrap();
    d.brake_release().unwrap();
    c.session
        .wait_status_for("the loop seeing the arm ready", 60, |v| {
            v["reason"] == "Robot(ProgramStopped)"
        });
}

#[test]
fn the_cells_own_faults_stop_the_arm_and_each_has_its_recovery() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let ip = "127.0.0.107";
    let c = cell(ip, "127.0.0.108", 150, 329);
    // The program stopped from the pendant (dashboard `stop`): restarted on the resume.
    latched_fault(&c, "dashboard stop", Duration::from_millis(400), |_| {
        pendant(ip).stop().unwrap();
    });
    // A protective stop: UR lets it be unlocked 5 s after it happened, not before.
    latched_fault_then(
        &c,
        "protective stop",
        Duration::from_millis(400),
        |c| c.controller.cell("protective stop a bump"),
        |_| std::thread::sleep(Duration::from_secs(4)),
    );
    // Powered off from the pendant: the operator powers on and releases the brakes there.
    latched_fault_then(
        &c,
        "power off",
        Duration::from_millis(400),
        |_| pendant(ip).power_off().unwrap(),
        |c| power_on_and_release(c, ip),
    );
    // The emergency stop: a resume while it is pressed is refused and nothing moves; released,
    // powered and the brakes off, the resume brings the loop back.
    latched_fault_then(
        &c,
        "emergency stop",
        Duration::from_millis(400),
        |c| c.controller.cell("emergency stop"),
        |c| {
            c.resume();
            // The re-arm refused while it is pressed (waited for, not slept), nothing moved.
            let refused = |events: &Value| {
                events.as_array().is_some_and(|a| {
                    a.iter().any(|e| {
                        e["text"]
                            .as_str()
                            .is_some_and(|t| t.starts_with("re-arm refused: emergency stop"))
                    })
                })
            };
            mocomp_testkit::wait_until("the re-arm refused", || {
                refused(&c.session.get("/api/events").1)
            });
            let (_, v) = c.session.get("/api/status");
            assert_eq!(v["mode"], "faulted", "{v}");
            // The injected fault still waits for the resume that is taken.
            c.injecting();
            c.controller.cell("emergency stop release");
            power_on_and_release(c, ip);
        },
    );
    let unplanned = c.unplanned();
    let v = c.finish_with_protective_stops(1);
    let ev = events(&v);
    eprintln!("{ev:?}");
    for (fault, recovered) in [
        (
            "Hold(Robot(ProgramStopped))",
            "re-armed: the control program running again",
        ),
        (
            "Hold(Robot(ProtectiveStop))",
            "re-armed: protective stop unlocked, the control program running again",
        ),
        (
            "Hold(Robot(NotRunning(",
            "re-armed: the control program running again",
        ),
        (
            "Hold(Robot(EmergencyStop))",
            "re-armed: the control program running again",
        ),
    ] {
        let at = ev
            .iter()
            .position(|e| e.starts_with(fault))
            .unwrap_or_else(|| panic!("no {fault}: {ev:?}"));
        let next = ev[at..]
            .iter()
            .find(|e| e.starts_with("re-arm"))
            .unwrap_or_else(|| panic!("no re-arm after {fault}: {ev:?}"));
        if fault.contains("EmergencyStop") {
            assert!(next.starts_with("re-arm refused: emergency stop"), "{ev:?}");
        } else {
            assert_eq!(next, recovered, "{ev:?}");
        }
    }
    assert_eq!(rearms(&ev), 4 + unplanned, "{ev:?}");
}

#[test]
fn tracker_stalls_resets_and_corruption_hold_or_coast_and_come_back_by_themselves() {
    // The tracker's faults are the tracker rules' to judge: a short gap is coasted on the
    // prediction, a longer one holds the arm (the head unknown, moving blind is worse than
    // standing), and fresh samples bring the loop back by a path, without the operator: the
    // controller never stopped the arm. Corrupted bytes never become a pose: the body's CRC
    // drops a message, a broken header drops the connection, and the client connects again.
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = cell_with(
        "127.0.0.109",
        "127.0.0.110",
        120,
        429,
        &Extras {
            tracker: Some(("127.0.0.111", "127.0.0.112")),
            ..Extras::default()
        },
    );
    let igtl = c.igtl.as_ref().unwrap();
    c.tracking("before the tracker's faults");
    // 100 ms: coasted (tracker_stale_s 75 ms + coast_s 150 ms).
    igtl.stall(Duration::from_millis(100));
    std::thread::sleep(Duration::from_millis(300));
    c.tracking("after a 100 ms tracker stall");
    // 1 s: held, the arm still, then back.
    let t0 = monotonic_s();
    igtl.stall(Duration::from_secs(1));
    c.wait_for("held for a stale tracker", 5, held_for_a_stale_tracker);
    c.tracking("after a 1 s tracker stall");
    let still = c.monitor.still_after(t0, Duration::from_millis(100));
    eprintln!("1 s tracker stall: arm still after {still:?}");
    assert!(
        still.is_some_and(|d| d < Duration::from_secs(1)),
        "{still:?}"
    );
    // The connection reset: the client connects again.
    igtl.reset();
    mocomp_testkit::wait_until("the tracker's client connected again", || {
        igtl.connections() >= 2
    });
    c.tracking("after a tracker reset");
    // The tracker server restarted: gone for 2 s (its connection lost, new ones unanswered),
    // then back.
    let before = igtl.connections();
    igtl.cut();
    igtl.reset();
    c.wait_for("held while the tracker is gone", 5, |v| {
        v["mode"] == "holding"
    });
    std::thread::sleep(Duration::from_secs(2));
    igtl.restore();
    c.tracking("after the tracker server came back");
    assert!(igtl.connections() > before, "connected again");
    // Corrupted bytes, in a message body and in headers.
    for n in [8, 200] {
        igtl.corrupt(Direction::Downstream, n);
        mocomp_testkit::wait_until("the corrupted bytes sent", || igtl.faults_spent());
        c.tracking(&format!("after {n} corrupted tracker bytes"));
    }
    let unplanned = c.unplanned();
    let (v, on_goal) = c.finish_logged(0);
    let ev = events(&v);
    eprintln!("{ev:?}");
    // The tracker's faults never latch the robot side (a stale robot state of its own, on a
    // busy machine, is the robot rules' and resumes by itself: not counted here); the machine's
    // own stops are the only robot faults.
    assert_eq!(rearms(&ev), unplanned, "{ev:?}");
    assert!(robot_faults(&ev) <= unplanned, "{ev:?}");
    assert!(ev.iter().any(|e| e.starts_with("Coasting")), "{ev:?}");
    assert!(
        ev.iter().any(|e| e.starts_with("Hold(TrackerStale")),
        "{ev:?}"
    );
    // No corrupted pose reached the loop as a head that jumped.
    assert!(!ev.iter().any(|e| e.starts_with("Outlier")), "{ev:?}");
    on_goal.check(5.0, 1.0, &v);
}

#[test]
fn a_step_in_the_trackers_clock_holds_the_arm_until_the_client_rebases_then_comes_back() {
    // The tracker computer's clock steps back a second mid-compensation (NTP correcting it), its
    // clock not synchronised with ours (timestamps "estimated", its latency given). Every sample
    // after the step looks a second old: not taken, the arm held for a stale tracker, until the
    // client has seen CONFIRM_S of them all that late and re-bases its offset; then fresh
    // samples bring the loop back by a path, by itself. No sample from before the step is read
    // as a jump of the head.
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = cell_with(
        "127.0.0.115",
        "127.0.0.116",
        60,
        629,
        &Extras {
            changes: &[
                ("timestamps = \"auto\"", "timestamps = \"estimated\""),
                ("fixed_latency_s = 0.0", "fixed_latency_s = 0.02"),
                ("clock_step_s = 0.0", "clock_step_s = -1.0"),
                ("clock_step_at_s = 0.0", "clock_step_at_s = 14.0"),
            ],
            ..Extras::default()
        },
    );
    c.tracking("before the tracker's clock steps");
    c.wait_for(
        "held when the tracker's clock stepped",
        20,
        held_for_a_stale_tracker,
    );
    c.tracking("after the tracker's clock stepped");
    let unplanned = c.unplanned();
    let (v, on_goal) = c.finish_logged(0);
    let ev = events(&v);
    eprintln!("{ev:?}; tracker link {}", v["tracker"]);
    assert_eq!(v["tracker"]["clock_steps"], 1, "{v}");
    assert_eq!(v["tracker"]["connections"], 1, "{v}");
    assert!(!ev.iter().any(|e| e.starts_with("Outlier")), "{ev:?}");
    assert_eq!(rearms(&ev), unplanned, "{ev:?}");
    assert!(robot_faults(&ev) <= unplanned, "{ev:?}");
    let stale = ev
        .iter()
        .filter(|e| e.starts_with("Hold(TrackerStale"))
        .count();
    assert!(stale >= 1, "{ev:?}");
    on_goal.check(5.0, 1.0, &v);
}

#[test]
fn a_killed_loop_leaves_the_arm_still_within_the_watchdog_and_a_stop() {
    // SIGKILL mid-compensation: no handler runs, no stop is sent. The control program's watchdog
    // (no command for 50 ms) stops the program, and the arm brakes.
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let mut c = cell("127.0.0.113", "127.0.0.114", 60, 529);
    c.tracking("before the kill");
    // Into a fast part of the nod.
    std::thread::sleep(Duration::from_millis(300));
    let t0 = monotonic_s();
    c.session.kill();
    let moving = c.monitor.top_speed(t0 - 0.05, t0);
    let still = c
        .monitor
        .still_after(t0, Duration::from_millis(500))
        .expect("the arm never stood still");
    eprintln!(
        "SIGKILL at {moving:.3} rad/s: arm still {:.0} ms later",
        still.as_secs_f64() * 1e3
    );
    assert!(
        c.controller.log().contains("RTDE watchdog"),
        "{}",
        c.controller.log()
    );
    // The watchdog's 50 ms, then stopj's 4 rad/s² (UR's and URCL's) from the speed it had, and
    // 10 ms for the kill to land and the controller's states to say so.
    let bound = 0.050 + moving / 4.0 + 0.010;
    assert!(
        still.as_secs_f64() < bound,
        "{still:?} at {moving:.3} rad/s: beyond {bound:.3} s"
    );
}
