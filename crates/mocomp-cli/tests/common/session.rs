#![allow(clippy::print_stderr, clippy::unwrap_used, clippy::panic)] // test support: a child's stderr passed on
//! `mocomp run --dashboard` in a child process, driven through its console's HTTP API as the
//! operator's browser would: the console tests, and the fault tests' operator (hold, resume).

use mocomp_testkit::{TempDir, workspace_root};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Writes the example configuration `example` (in `examples/`) with its simulated robot on
/// `host` into `dir`; its path.
pub fn write_example(dir: &TempDir, example: &str, host: &str) -> String {
    let path = dir.path("run.toml");
    let cfg = std::fs::read_to_string(workspace_root().join("examples").join(example))
        .unwrap()
        .replace("host = \"127.0.0.2\"", &format!("host = \"{host}\""));
    std::fs::write(&path, cfg).unwrap();
    path
}

/// A `mocomp run --dashboard` child and its console's address and token.
#[derive(Debug)]
pub struct Session {
    child: Child,
    /// `http://127.0.0.1:PORT`.
    pub base: String,
    /// The token from the printed link.
    pub token: String,
    agent: ureq::Agent,
    stdout: Option<std::thread::JoinHandle<String>>,
}

/// How long a session's run may last: a test ends its session itself (the page's or the API's
/// stop, or dropping it), so this only ends a hung one. A run that ended by its own clock while
/// a starved browser was still at work (a 90 s run, two suites and stress-ng on two cores)
/// failed the test that needed it.
const HUNG_S: &str = "900";

/// How long a run may take to end after its stop, or the console to answer a request, before
/// the test calls it hung, s.
const ENDED_AFTER_STOP_S: u64 = 120;

impl Session {
    /// Starts the example configuration `example` (in `examples/`) with its simulated robot on
    /// `host`, the console on a free loopback port, plus `extra` options.
    pub fn start(dir: &TempDir, example: &str, host: &str, extra: &[&str]) -> Session {
        Self::start_file(&write_example(dir, example, host), extra)
    }

    /// Starts the configuration at `path`, the console on a free loopback port.
    pub fn start_file(path: &str, extra: &[&str]) -> Session {
        let mut args = vec!["run", "--config", path, "--quiet", "--seconds", HUNG_S];
        args.extend(["--dashboard", "127.0.0.1:0"]);
        args.extend(extra);
        Self::spawn(&args)
    }

    /// Runs `mocomp` with `args` (which ask for a console); its first line names the console.
    pub fn spawn(args: &[&str]) -> Session {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mocomp"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut lines = BufReader::new(child.stdout.take().unwrap());
        // The first line names the console.
        let mut first = String::new();
        lines.read_line(&mut first).unwrap();
        let stdout = std::thread::spawn(move || collect(lines));
        Self::with_url(child, &first, stdout)
    }

    /// Runs `mocomp` with `args` (which ask for a console and `--json`): the console's line
    /// comes on standard error, standard output is the JSON summary alone. The rest of standard
    /// error is passed on to the test's.
    pub fn spawn_json(args: &[&str]) -> Session {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mocomp"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let mut first = String::new();
        while !first.starts_with("dashboard: ") {
            first.clear();
            assert!(
                err.read_line(&mut first).unwrap() > 0,
                "the run ended before naming its console"
            );
            eprint!("{first}");
        }
        std::thread::spawn(move || {
            for line in err.lines().map_while(Result::ok) {
                eprintln!("{line}");
            }
        });
        let out = BufReader::new(child.stdout.take().unwrap());
        let stdout = std::thread::spawn(move || collect(out));
        Self::with_url(child, &first, stdout)
    }

    fn with_url(child: Child, first: &str, stdout: std::thread::JoinHandle<String>) -> Session {
        let url = first
            .strip_prefix("dashboard: ")
            .unwrap_or_else(|| panic!("first line: {first:?}"))
            .trim()
            .to_string();
        let (base, token) = url.split_once("/?token=").unwrap();
        let agent: ureq::Agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            // An answer comes as soon as the console gives it: the limit only ends a hung
            // request, past stalls of a starved machine's scheduler and I/O.
            .timeout_global(Some(Duration::from_secs(ENDED_AFTER_STOP_S)))
            .build()
            .into();
        Session {
            child,
            base: base.to_string(),
            token: token.to_string(),
            agent,
            stdout: Some(stdout),
        }
    }

    /// GET `path` (no token), its status code and JSON.
    pub fn get(&self, path: &str) -> (u16, Value) {
        let mut r = self
            .agent
            .get(format!("{}{path}", self.base))
            .call()
            .unwrap();
        (
            r.status().as_u16(),
            r.body_mut().read_json().unwrap_or(Value::Null),
        )
    }

    /// POST `body` to `path` with these headers.
    pub fn post(&self, path: &str, headers: &[(&str, &str)], body: &Value) -> (u16, Value) {
        let mut req = self.agent.post(format!("{}{path}", self.base));
        for (k, v) in headers {
            req = req.header(*k, *v);
        }
        let mut r = req.send_json(body).unwrap();
        (
            r.status().as_u16(),
            r.body_mut().read_json().unwrap_or(Value::Null),
        )
    }

    /// POST with the token.
    pub fn post_auth(&self, path: &str, body: &Value) -> (u16, Value) {
        let bearer = format!("Bearer {}", self.token);
        self.post(path, &[("Authorization", &bearer)], body)
    }

    /// Waits (up to 30 s) until the status satisfies `f`; returns it.
    pub fn wait_status(&self, what: &str, f: impl Fn(&Value) -> bool) -> Value {
        self.wait_status_for(what, 30, f)
    }

    /// Waits (up to `seconds`) until the status satisfies `f`; returns it.
    pub fn wait_status_for(&self, what: &str, seconds: u64, f: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + Duration::from_secs(seconds);
        loop {
            let (code, s) = self.get("/api/status");
            assert_eq!(code, 200, "{s}");
            if f(&s) {
                return s;
            }
            if Instant::now() >= deadline {
                let (_, events) = self.get("/api/events");
                panic!("waiting for {what}; last status {s}; events {events}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// [`Self::wait_status`], re-arming a latched `RobotStale` as an operator would (no robot
    /// state for 250 ms: this machine stopped the controller's process or the loop's that long,
    /// seen with two suites and `stress-ng` on two cores), once a second of loop time at most,
    /// printed. For waits where no operator's hold is meant (a resume ends one).
    #[allow(dead_code)] // not every test file that shares this module uses it
    pub fn wait_status_rearming(&self, what: &str, f: impl Fn(&Value) -> bool) -> Value {
        let deadline = Instant::now() + mocomp_testkit::HUNG;
        let mut rearmed_at = f64::NEG_INFINITY;
        loop {
            let (code, s) = self.get("/api/status");
            assert_eq!(code, 200, "{s}");
            if f(&s) {
                return s;
            }
            let t = s["t"].as_f64().unwrap_or(0.0);
            if latched_stale(&s) && t - rearmed_at > 1.0 {
                eprintln!(
                    "no robot state for 250 ms (this machine stalled a process): the loop latched \
                     RobotStale; re-arming as an operator would"
                );
                let (code, _) = self.post_auth("/api/resume", &serde_json::json!({}));
                assert_eq!(code, 200);
                rearmed_at = t;
            }
            if Instant::now() >= deadline {
                let (_, events) = self.get("/api/events");
                panic!("waiting for {what}; last status {s}; events {events}");
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits until the loop has tracked for `seconds` of its own time without a break, doing
    /// what an operator does when the controller stopped the arm by itself: a simulated
    /// controller shares this machine, whose host can stop one of its virtual CPUs for 100 ms
    /// (seen with `perf sched`), and its 50 ms watchdog then stops the program as a real
    /// controller would for a frozen PC. Such a stop (`watchdog_stops()`, the controller's own
    /// count, has grown past the resumes given) is printed and resumed. Returns how many were.
    /// So is the loop's own latched `RobotStale` fault: no state for `robot_rearm_after_s`
    /// (250 ms) means this machine stopped the controller's process or the loop's for that long
    /// (seen beside `stress-ng --cpu 2` and a build), which a real cell's operator re-arms
    /// too; those are printed and not counted. The deadline (wall seconds) only catches a run
    /// that never gets there.
    #[allow(dead_code)] // not every test file that shares this module uses it
    pub fn track_for(
        &self,
        seconds: f64,
        deadline_s: u64,
        watchdog_stops: &dyn Fn() -> usize,
    ) -> usize {
        let deadline = Instant::now() + Duration::from_secs(deadline_s);
        let mut resumed = 0;
        let mut since: Option<f64> = None;
        // The loop time of the last re-arm of a latched stale state (one per second at most:
        // the recovery takes a few cycles to show).
        let mut rearmed_at = f64::NEG_INFINITY;
        loop {
            let (_, v) = self.get("/api/status");
            let t = v["t"].as_f64().unwrap_or(0.0);
            let stopped = v["reason"]
                .as_str()
                .is_some_and(|r| r.starts_with("Robot(ProgramStopped"));
            if v["mode"] == "tracking" {
                if t - *since.get_or_insert(t) >= seconds {
                    return resumed;
                }
            } else {
                since = None;
                if v["mode"] == "faulted" && stopped && watchdog_stops() > resumed {
                    eprintln!(
                        "the controller's watchdog stopped the program (this machine stalled): resuming as an operator would"
                    );
                    let (code, _) = self.post_auth("/api/resume", &serde_json::json!({}));
                    assert_eq!(code, 200);
                    resumed += 1;
                } else if latched_stale(&v) && t - rearmed_at > 1.0 {
                    eprintln!(
                        "no robot state for 250 ms (this machine stalled a process): the loop \
                         latched RobotStale; re-arming as an operator would"
                    );
                    let (code, _) = self.post_auth("/api/resume", &serde_json::json!({}));
                    assert_eq!(code, 200);
                    rearmed_at = t;
                }
            }
            assert!(
                Instant::now() < deadline,
                "never tracked for {seconds} s; last status {v}; events {}",
                self.get("/api/events").1
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Kills the run (SIGKILL: no handler runs, no stop is sent), and waits for it.
    pub fn kill(&mut self) {
        self.child.kill().unwrap();
        self.child.wait().unwrap();
    }

    /// Waits for the run to end; its exit success and standard output. The wait returns as soon
    /// as the run has ended, so its deadline only catches a run that hangs: on a starved machine
    /// (two suites and `stress-ng` on two cores, the kernel's I/O workers once stalled 36 s) the
    /// stop, the logger's last writes and the report took longer than the 15 s once allowed. A
    /// run that ends late says how late.
    pub fn finish(mut self) -> (bool, String) {
        let asked = Instant::now();
        let status = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s;
            }
            if asked.elapsed() > Duration::from_secs(ENDED_AFTER_STOP_S) {
                // The console may be down already: what it last said, if it still answers.
                let last = self
                    .agent
                    .get(format!("{}/api/status", self.base))
                    .call()
                    .ok()
                    .and_then(|mut r| r.body_mut().read_to_string().ok());
                self.child.kill().ok();
                panic!(
                    "the run did not end {ENDED_AFTER_STOP_S} s after its stop; last status {last:?}"
                );
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        if asked.elapsed() > Duration::from_secs(15) {
            eprintln!(
                "the run ended {:.1} s after its stop",
                asked.elapsed().as_secs_f64()
            );
        }
        (
            status.success(),
            self.stdout.take().unwrap().join().unwrap(),
        )
    }
}

/// The loop latched a stale robot state (no state for `robot_rearm_after_s`): faulted until an
/// operator re-arms it.
pub fn latched_stale(status: &Value) -> bool {
    status["mode"] == "faulted" && status["reason"] == "RobotStale"
}

/// Every line of `lines`, as they come, until it closes.
fn collect(lines: impl BufRead) -> String {
    let mut rest = String::new();
    for line in lines.lines() {
        rest.push_str(&line.unwrap_or_default());
        rest.push('\n');
    }
    rest
}

impl Drop for Session {
    fn drop(&mut self) {
        self.child.kill().ok();
        self.child.wait().ok();
    }
}

fn python() -> std::path::PathBuf {
    std::env::var_os("MOCOMP_PYTHON")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| workspace_root().join(".venv/bin/python"))
}

/// Runs the browser helper (`interop/console_browser.py`) on the session's console in `mode`,
/// its screenshots into `shots`; what it saw.
pub fn browse(s: &Session, shots: &str, mode: &str) -> Value {
    // A real headless Chromium (Debian's chromium and chromium-driver) through Selenium in the
    // test venv; a missing browser, driver or Selenium fails here, with how to install them.
    for p in ["/usr/bin/chromium", "/usr/bin/chromedriver"] {
        let p = std::env::var(if p.ends_with("driver") {
            "MOCOMP_CHROMEDRIVER"
        } else {
            "MOCOMP_CHROMIUM"
        })
        .unwrap_or_else(|_| p.to_string());
        assert!(
            std::path::Path::new(&p).exists(),
            "{p} missing: apt-get install chromium chromium-driver (scripts/test.sh does)"
        );
    }
    std::fs::create_dir_all(shots).unwrap();
    let out = Command::new(python())
        .arg(workspace_root().join("interop/console_browser.py"))
        .arg(format!("{}/?token={}", s.base, s.token))
        .arg(shots)
        .arg(mode)
        .stderr(Stdio::inherit())
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run the browser helper: {e}; {}",
                mocomp_testkit::INSTALL_HINT
            )
        });
    assert!(
        out.status.success(),
        "the browser helper's {mode} session failed: its traceback and the driver's log are \
         above (a ModuleNotFoundError there means the peers are missing: {})",
        mocomp_testkit::INSTALL_HINT
    );
    let seen: Value = serde_json::from_slice(&out.stdout).unwrap();
    eprintln!("console in the browser ({mode}): {seen}");
    seen
}
