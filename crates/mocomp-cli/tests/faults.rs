#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! The faults of a real cell (issue 29), injected while `mocomp run` compensates against a
//! controller in another process: `mocomp ursim` started on its own, reached through the test
//! kit's fault-injecting relay (RTDE, dashboard and script ports on an address of the relay's
//! own), the operator at the console. A monitor that is not mocomp reads the controller's own
//! RTDE stream directly, beside the loop's connection, and says when the arm stood still.
//!
//! For each fault: the loop's named event; the arm still (and how soon); a fault the controller
//! reports, or a gap long enough that it stopped the arm itself, stays until the operator
//! resumes, and then the loop comes back from where the arm is, by a path (never a silent jump
//! back); every cycle is in the log.

mod common;
use common::example_changed;
use common::session::Session;
use mocomp_testkit::TempDir;
use mocomp_testkit::controller::ChildController;
use mocomp_testkit::proxy::{Direction, FaultProxy};
use mocomp_ur::connection::RtdeConnection;
use serde_json::{Value, json};
use std::net::SocketAddr;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// One cell at a time in this file: a loop and a controller at real-time priority each, on two
/// cores.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The controller's own view of the arm, read over a connection of its own: when each state
/// came, the fastest joint's speed, the runtime state.
struct Monitor {
    samples: Arc<Mutex<Vec<(Instant, f64, i32)>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Monitor {
    fn start(controller: SocketAddr) -> Self {
        let samples = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let mut conn = RtdeConnection::connect(controller, Duration::from_secs(2)).unwrap();
        conn.negotiate().unwrap();
        let recipe = conn
            .setup_outputs(500.0, &["actual_qd", "runtime_state"])
            .unwrap();
        conn.start().unwrap();
        let thread = {
            let (samples, stop) = (Arc::clone(&samples), Arc::clone(&stop));
            std::thread::spawn(move || {
                let mut values = Vec::new();
                while !stop.load(Ordering::Relaxed) {
                    if conn.receive(&recipe, &mut values, false).is_err() {
                        continue;
                    }
                    let qd = values[0].as_vec6().unwrap();
                    let speed = qd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    let runtime = values[1].as_f64().unwrap() as i32;
                    samples
                        .lock()
                        .unwrap()
                        .push((Instant::now(), speed, runtime));
                }
            })
        };
        Self {
            samples,
            stop,
            thread: Some(thread),
        }
    }

    /// The fastest joint's top speed in [from, to), rad/s.
    fn top_speed(&self, from: Instant, to: Instant) -> f64 {
        let s = self.samples.lock().unwrap();
        s.iter()
            .filter(|x| x.0 >= from && x.0 < to)
            .fold(0.0, |m, x| m.max(x.1))
    }

    /// How long after `t0` the arm came to stand (every joint below 1 mrad/s) and stayed there
    /// for `for_s`; `None` if it never did.
    fn still_after(&self, t0: Instant, stay: Duration) -> Option<Duration> {
        let s = self.samples.lock().unwrap();
        let after: Vec<_> = s.iter().filter(|x| x.0 >= t0).collect();
        (0..after.len()).find_map(|i| {
            let start = after[i].0;
            let end = start + stay;
            let through: Vec<_> = after[i..].iter().take_while(|x| x.0 < end).collect();
            let long_enough = after.last().is_some_and(|l| l.0 >= end);
            (long_enough && through.iter().all(|x| x.1 < 1e-3)).then(|| start - t0)
        })
    }
}

impl Drop for Monitor {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join().ok();
        }
    }
}

/// A controller behind the relay, the monitor on it, and the loop with its console.
struct Cell {
    controller: ChildController,
    rtde: FaultProxy,
    _others: [FaultProxy; 2],
    monitor: Monitor,
    session: Session,
    dir: TempDir,
}

/// Starts `mocomp ursim` on `controller_ip` (behind the head), the relay on `relay_ip` (RTDE,
/// dashboard, script ports), and `mocomp run` against the relay for at most `seconds`, with its
/// CSV log.
fn cell(controller_ip: &str, relay_ip: &str, seconds: u32, seed: u64) -> Cell {
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
    let config = example_changed(&dir, relay_ip, &[("simulate = true ", "simulate = false")]);
    let (csv, secs) = (dir.path("run.csv"), seconds.to_string());
    let session = Session::spawn_json(&[
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
    ]);
    Cell {
        controller,
        rtde,
        _others: others,
        monitor,
        session,
        dir,
    }
}

impl Cell {
    /// Waits until the loop has tracked for a second.
    fn tracking(&self, what: &str) {
        let s = &self.session;
        s.wait_status_for(&format!("tracking {what}"), 40, |v| v["mode"] == "tracking");
        std::thread::sleep(Duration::from_secs(1));
        s.wait_status_for(&format!("tracking {what}"), 5, |v| v["mode"] == "tracking");
    }

    /// Ends the run; its JSON summary. Checks what every run must show: no protective stop
    /// (the controller refused no setpoint), the arm at a standstill, every cycle logged.
    fn finish(self) -> Value {
        let (code, _) = self.session.post_auth("/api/stop", &json!({}));
        assert_eq!(code, 200);
        let (ok, out) = self.session.finish();
        assert!(ok, "the run failed: {out}");
        let v: Value = serde_json::from_str(&out).unwrap();
        assert!(
            self.controller.protective_stops().is_empty(),
            "{:?}",
            self.controller.protective_stops()
        );
        assert_eq!(v["protective_stops"], 0, "{v}");
        assert_eq!(v["stop"]["outcome"], "standstill", "{v}");
        assert_eq!(v["log_records_dropped"], 0, "{v}");
        let rows = csv::Reader::from_path(self.dir.path("run.csv"))
            .unwrap()
            .records()
            .count();
        assert_eq!(
            rows as u64,
            v["cycles"].as_u64().unwrap(),
            "every cycle logged"
        );
        v
    }
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
    c.tracking(&format!("before the {what}"));
    let t0 = Instant::now();
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
    let quiet_from = t0 + still;
    let top = c.monitor.top_speed(quiet_from, Instant::now());
    assert!(
        top < 1e-3,
        "{what}: the arm moved while latched ({top} rad/s)"
    );
    eprintln!(
        "{what}: arm still {:.0} ms after the fault",
        still.as_secs_f64() * 1e3
    );
    // The operator resumes: the robot's recovery, then back by a path.
    let (code, _) = s.post_auth("/api/resume", &json!({}));
    assert_eq!(code, 200);
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
    let v = c.finish();
    let ev = events(&v);
    assert_rearmed_each_time(&ev, 3, "the control program running again");
}

/// `n` faults latched, each re-armed by the operator (`recovered`: the session's note of what
/// the recovery did), each followed by the loop's resume.
fn assert_rearmed_each_time(ev: &[String], n: usize, recovered: &str) {
    let rearms: Vec<usize> = (0..ev.len()).filter(|&i| ev[i] == "Rearmed").collect();
    assert_eq!(rearms.len(), n, "{ev:?}");
    for i in rearms {
        assert!(
            ev[i - 1] == format!("re-armed: {recovered}"),
            "the recovery before the re-arm: {ev:?}"
        );
        // Since the resume before it: the fault that latched.
        let since = ev[..i].iter().rposition(|e| e == "Resume").unwrap_or(0);
        assert!(
            ev[since..i].iter().any(|e| e.starts_with("Hold(Robot")),
            "a fault named before the re-arm: {ev:?}"
        );
        assert_eq!(ev.get(i + 1).map(String::as_str), Some("Resume"), "{ev:?}");
    }
}

#[test]
fn a_reset_rtde_connection_is_reconnected_on_the_operators_resume() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let c = cell("127.0.0.103", "127.0.0.104", 90, 129);
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
    let v = c.finish();
    let ev = events(&v);
    assert_rearmed_each_time(&ev, 2, "connected again, the control program running");
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
    // 50 ms watchdog), and it comes back by itself by a path.
    c.rtde.stall(Duration::from_millis(40));
    c.tracking("after a 40 ms stall");
    let v = c.finish();
    let ev = events(&v);
    assert!(!ev.iter().any(|e| e == "Rearmed"), "{ev:?}");
    eprintln!("{ev:?}");
}
