//! A simulated UR controller in a process of its own: `mocomp ursim` started as a real controller
//! would be (its own start pose, its own real-time priority), its printed events collected, and
//! the whole controller stalled on demand (`SIGSTOP`, then `SIGCONT`): its clock, its state stream
//! and its command input stop together, as when a controller's computer is held up, and it then
//! makes up the cycles it missed as the simulator does for a late wake-up.

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// `mocomp ursim` running in a child process; killed when dropped.
#[derive(Debug)]
pub struct ChildController {
    child: Child,
    log: Arc<Mutex<String>>,
    /// Its standard input: the cell's events (`--cell-stdin`).
    cell: Mutex<Option<std::process::ChildStdin>>,
}

impl ChildController {
    /// Starts `bin ursim --model MODEL --host HOST --initial-joints Q --cell-stdin` plus
    /// `extra`, and waits (10 s at most) until it serves.
    pub fn start(bin: &Path, model: &str, host: &str, q: [f64; 6], extra: &[&str]) -> Self {
        let joints = q.map(|v| format!("{v:.6}")).join(",");
        let mut child = Command::new(bin)
            .args(["ursim", "--model", model, "--host", host])
            .arg(format!("--initial-joints={joints}"))
            .arg("--cell-stdin")
            .args(extra)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {} ursim: {e}", bin.display()));
        let log = Arc::new(Mutex::new(String::new()));
        for stream in [
            child
                .stdout
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
            child
                .stderr
                .take()
                .map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        ]
        .into_iter()
        .flatten()
        {
            let log = Arc::clone(&log);
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    if let Ok(mut l) = log.lock() {
                        l.push_str(&line);
                        l.push('\n');
                    }
                }
            });
        }
        let cell = Mutex::new(child.stdin.take());
        let c = Self { child, log, cell };
        crate::wait_until(
            &format!("the simulated controller on {host} to serve"),
            || c.log().contains("RTDE "),
        );
        c
    }

    /// Everything it printed so far (its address line, then its events).
    pub fn log(&self) -> String {
        self.log.lock().map(|l| l.clone()).unwrap_or_default()
    }

    /// The protective stops and refused setpoints it reported.
    pub fn protective_stops(&self) -> Vec<String> {
        self.log()
            .lines()
            .filter(|l| l.contains("protective stop") || l.contains("C204A3"))
            .map(str::to_string)
            .collect()
    }

    /// Something happens in the cell (`protective stop [why]`, `emergency stop`, `emergency stop
    /// release`), as a person in the room causes it.
    pub fn cell(&self, event: &str) {
        use std::io::Write;
        let mut g = self
            .cell
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let Some(stdin) = g.as_mut() else {
            panic!("the controller's standard input is closed");
        };
        writeln!(stdin, "{event}")
            .and_then(|()| stdin.flush())
            .unwrap_or_else(|e| panic!("telling the controller {event:?}: {e}"));
    }

    /// Holds the whole controller for `pause` (stopped, then continued); returns how long it
    /// really stood (the sleep between the signals is the scheduler's to keep).
    pub fn stall(&self, pause: Duration) -> Duration {
        let pid = Pid::from_raw(i32::try_from(self.child.id()).unwrap_or(i32::MAX));
        let t0 = Instant::now();
        kill(pid, Signal::SIGSTOP).unwrap_or_else(|e| panic!("SIGSTOP: {e}"));
        std::thread::sleep(pause);
        kill(pid, Signal::SIGCONT).unwrap_or_else(|e| panic!("SIGCONT: {e}"));
        t0.elapsed()
    }
}

impl Drop for ChildController {
    fn drop(&mut self) {
        let pid = Pid::from_raw(i32::try_from(self.child.id()).unwrap_or(i32::MAX));
        // A test that failed mid-stall leaves it stopped: continue it, then kill it.
        kill(pid, Signal::SIGCONT).ok();
        self.child.kill().ok();
        self.child.wait().ok();
    }
}
