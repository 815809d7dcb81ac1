//! Test support shared by mocomp's test suites (a dev-dependency only):
//! - [`PythonPeer`]: a third-party implementation driven through a helper script in `interop/`,
//!   one JSON request per line and one JSON answer per line, run in the workspace's `.venv` (or
//!   the Python named by `MOCOMP_PYTHON`). A missing peer is a test failure that says how to
//!   install it, never a skip.
//! - [`SplitMix64`]: a tiny seeded generator for tests that must not depend on a RNG crate's
//!   version.
//! - [`controller`]: `mocomp ursim` in a process of its own, as a real controller is (its own
//!   start pose and priority), with its event log, and stalls injected by stopping the process.
//! - [`proxy`]: a fault-injecting TCP relay between mocomp and a server (the controller, the
//!   tracker server): delay, jitter, stalls, cuts, resets, corrupted and dropped bytes, on
//!   command from the test.
//! - [`nifti`]: NIfTI-1 volumes made byte by byte (phantoms for what reads an MRI).
//! - [`mem`]: an in-memory robot (wherever it was commanded) and a scripted pose source, for the
//!   loop's rules and filter without sockets.
//! - [`TempDir`]: a scratch directory removed when dropped; [`listening_port`] (the port a child
//!   process bound itself, for peers that cannot print it) and [`wait_until`] for socket and
//!   thread tests; [`proptest_config`] with a fixed seed.
//!
//! There is deliberately no "find a free port" helper: a port probed free and bound later can be
//! taken in between. Servers bind port 0 (or an address of their own) and report what they got.
//!
//! **Limits.** A dev-dependency only: never in a production crate's dependencies.
#![allow(clippy::panic)] // test support: failures are panics with a message

pub mod anatomy;
pub mod controller;
pub mod fuzz;
pub mod mem;
pub mod nifti;
pub mod proxy;

use serde_json::Value;
use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

/// The workspace root (two levels above this crate).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The Python of the Azure Kinect peer's venv.
fn k4a_python() -> PathBuf {
    std::env::var_os("MOCOMP_K4A_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace_root().join(".venv-k4a/bin/python"))
}

/// The Azure Kinect SDK's libraries (libk4a, libk4arecord 1.4) that the PyPI wheel
/// `pyk4a-bundle` ships, in the test venv `.venv-k4a` (or `MOCOMP_K4A_SDK_DIR`). Panics, with
/// install instructions, when they are not there: a test that needs the SDK fails without it.
pub fn k4a_sdk_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("MOCOMP_K4A_SDK_DIR") {
        return PathBuf::from(d);
    }
    let lib = workspace_root().join(".venv-k4a/lib");
    let found = std::fs::read_dir(&lib).ok().and_then(|entries| {
        entries
            .filter_map(Result::ok)
            .map(|e| e.path().join("site-packages/pyk4a_bundle.libs"))
            .find(|p| p.is_dir())
    });
    found.unwrap_or_else(|| {
        panic!(
            "the Azure Kinect SDK is missing: no pyk4a_bundle.libs under {}; install it with \
             `scripts/test.sh` (creates .venv-k4a), or `python3 -m venv .venv-k4a && \
             .venv-k4a/bin/pip install -r requirements-k4a.txt` in the workspace root",
            lib.display()
        )
    })
}

/// How to install the interop peers.
pub const INSTALL_HINT: &str = "install them with `scripts/test.sh` (creates .venv), or \
     `python3 -m venv .venv && .venv/bin/pip install -r requirements-interop.txt` in the \
     workspace root";

/// A running helper process.
#[derive(Debug)]
pub struct PythonPeer {
    name: String,
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
}

impl PythonPeer {
    /// Starts `interop/<helper>` and checks it answers `{"op": "version"}` with `version`.
    /// Panics, with install instructions, when Python or the peer package is missing.
    pub fn start(helper: &str, peer: &str, version: &str) -> PythonPeer {
        let python = std::env::var_os("MOCOMP_PYTHON")
            .map(PathBuf::from)
            .unwrap_or_else(|| workspace_root().join(".venv/bin/python"));
        Self::start_with(&python, helper, peer, version)
    }

    /// [`PythonPeer::start`] in the Azure Kinect peer's own venv (`.venv-k4a`, or
    /// `MOCOMP_K4A_PYTHON`): `pyk4a-bundle` is built against NumPy 1, the other peers need 2.
    pub fn start_k4a(helper: &str, peer: &str, version: &str) -> PythonPeer {
        Self::start_with(&k4a_python(), helper, peer, version)
    }

    /// The helper's process id: a test may stop and continue it (`kill -STOP`), a peer that is
    /// not scheduled for a while.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    fn start_with(python: &std::path::Path, helper: &str, peer: &str, version: &str) -> PythonPeer {
        let root = workspace_root();
        let mut child = Command::new(python)
            .arg(root.join("interop").join(helper))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap_or_else(|e| {
                panic!(
                    "interop peer {peer} missing: cannot run {}: {e}; {INSTALL_HINT}",
                    python.display()
                )
            });
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            panic!("interop peer {peer}: no pipes to the helper");
        };
        let mut p = PythonPeer {
            name: peer.to_string(),
            child,
            stdin,
            stdout: BufReader::new(stdout),
        };
        let v = p
            .try_request(&serde_json::json!({"op": "version"}))
            .unwrap_or_else(|e| {
                panic!(
                    "interop peer {peer} missing ({e}; see Python's message above); {INSTALL_HINT}"
                )
            });
        let got = v["version"].as_str().unwrap_or("?");
        assert_eq!(
            got, version,
            "interop peer {peer}: requirements-interop.txt pins {version}, found {got}"
        );
        p
    }

    /// Sends one request and reads one answer; an answer with `"error"` is an error.
    pub fn try_request(&mut self, req: &Value) -> Result<Value, String> {
        writeln!(self.stdin, "{req}").map_err(|e| e.to_string())?;
        self.stdin.flush().map_err(|e| e.to_string())?;
        let mut line = String::new();
        let n = self
            .stdout
            .read_line(&mut line)
            .map_err(|e| e.to_string())?;
        if n == 0 {
            return Err("the helper exited".into());
        }
        let v: Value = serde_json::from_str(&line)
            .map_err(|e| format!("{e} in {:?}", line.chars().take(120).collect::<String>()))?;
        if let Some(e) = v.get("error") {
            return Err(format!("helper error: {e}"));
        }
        Ok(v)
    }

    /// Like [`Self::try_request`], panicking with the peer's name on error.
    pub fn request(&mut self, req: &Value) -> Value {
        match self.try_request(req) {
            Ok(v) => v,
            Err(e) => panic!("interop peer {}: {e}", self.name),
        }
    }
}

impl Drop for PythonPeer {
    fn drop(&mut self) {
        self.child.kill().ok();
        self.child.wait().ok();
    }
}

/// The TCP port process `pid` listens on (IPv4 or IPv6), read from `/proc`: for a third-party
/// server started on port 0 that does not print the port it got. Waits up to 10 s for the
/// listening socket to appear; panics naming the process otherwise.
pub fn listening_port(pid: u32) -> u16 {
    let mut port = None;
    wait_until(&format!("process {pid} to listen on a TCP port"), || {
        port = listening_ports(pid).into_iter().next();
        port.is_some()
    });
    port.unwrap_or_else(|| panic!("process {pid} listens on no port"))
}

fn listening_ports(pid: u32) -> Vec<u16> {
    // The process's socket inodes …
    let inodes: Vec<String> = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|d| {
            d.filter_map(Result::ok)
                .filter_map(|e| std::fs::read_link(e.path()).ok())
                .filter_map(|l| {
                    let l = l.to_string_lossy().into_owned();
                    l.strip_prefix("socket:[")
                        .and_then(|r| r.strip_suffix(']'))
                        .map(str::to_string)
                })
                .collect()
        })
        .unwrap_or_default();
    // … matched against the listening (state 0A) sockets of its network namespace.
    let mut ports = Vec::new();
    for table in ["tcp", "tcp6"] {
        let Ok(text) = std::fs::read_to_string(format!("/proc/{pid}/net/{table}")) else {
            continue;
        };
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split_whitespace().collect();
            if f.len() > 9 && f[3] == "0A" && inodes.iter().any(|i| i == f[9]) {
                let port = f[1]
                    .rsplit(':')
                    .next()
                    .and_then(|h| u16::from_str_radix(h, 16).ok());
                ports.extend(port);
            }
        }
    }
    ports
}

/// Now on `CLOCK_MONOTONIC`, s: the clock Rust's `Instant` and Python's `time.monotonic` both
/// read on Linux, so a test and a Python peer can compare times.
pub fn monotonic_s() -> f64 {
    use nix::time::{ClockId, clock_gettime};
    let t =
        clock_gettime(ClockId::CLOCK_MONOTONIC).unwrap_or_else(|e| panic!("CLOCK_MONOTONIC: {e}"));
    t.tv_sec() as f64 + t.tv_nsec() as f64 * 1e-9
}

/// How long a condition may take before a test calls it hung. It returns as soon as the
/// condition holds, so waiting long costs nothing when the code is right; two test suites and
/// `stress-ng` on two cores have held a thread back for seconds.
pub const HUNG: std::time::Duration = std::time::Duration::from_secs(60);

/// Polls `f` every 2 ms until it is true; panics naming `what` after [`HUNG`]. For tests on
/// threads and sockets, where fixed sleeps are flaky on loaded machines: a condition with a
/// deadline that only catches a hung test.
pub fn wait_until(what: &str, mut f: impl FnMut() -> bool) {
    let end = std::time::Instant::now() + HUNG;
    while !f() {
        if std::time::Instant::now() > end {
            panic!("timed out waiting for {what}");
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
}

/// Like [`wait_until`], but spins (yielding) instead of sleeping: for lockstep tests that hand
/// every cycle across threads, where a 2 ms sleep per hand-over would dominate.
pub fn spin_until(what: &str, mut f: impl FnMut() -> bool) {
    let end = std::time::Instant::now() + HUNG;
    while !f() {
        if std::time::Instant::now() > end {
            panic!("timed out waiting for {what}");
        }
        std::thread::yield_now();
    }
}

/// A proptest configuration with a fixed seed (failures reproduce) and no persistence files.
pub fn proptest_config(cases: u32, seed: u64) -> proptest::test_runner::Config {
    proptest::test_runner::Config {
        cases,
        max_global_rejects: 100 * cases,
        rng_seed: proptest::test_runner::RngSeed::Fixed(seed),
        failure_persistence: None,
        ..proptest::test_runner::Config::default()
    }
}

/// A temporary directory under the system's temp dir, removed when dropped.
#[derive(Debug)]
pub struct TempDir(PathBuf);

impl TempDir {
    /// Creates (fresh) `mocomp-<name>-<pid>-<n>`, `n` counting this process's directories: two
    /// tests of one binary that run at once and ask for the same name get a directory each
    /// (with the pid alone, the first to finish removed the other's files).
    pub fn new(name: &str) -> Self {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let d = std::env::temp_dir().join(format!("mocomp-{name}-{}-{n}", std::process::id()));
        std::fs::remove_dir_all(&d).ok();
        if let Err(e) = std::fs::create_dir_all(&d) {
            panic!("cannot create {}: {e}", d.display());
        }
        TempDir(d)
    }

    /// The path of `file` inside it, as a string (for command lines).
    pub fn path(&self, file: &str) -> String {
        self.0.join(file).to_string_lossy().into_owned()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// SplitMix64: a seeded, dependency-free sequence so failures reproduce.
#[derive(Debug, Clone, Default)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// Next raw 64-bit value.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Next value uniform in [0, 1).
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// An angle uniform in [−π, π).
    pub fn angle(&mut self) -> f64 {
        self.next_f64() * std::f64::consts::TAU - std::f64::consts::PI
    }

    /// A standard normal value (Box–Muller: one of the pair, the other discarded).
    pub fn gauss(&mut self) -> f64 {
        // 1 − u is in (0, 1]: the logarithm stays finite.
        let u = 1.0 - self.next_f64();
        let v = self.next_f64();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// Six angles uniform in [−π, π).
    pub fn joints(&mut self) -> [f64; 6] {
        std::array::from_fn(|_| self.angle())
    }
}

/// The compensation scene shared by the loop's tests and benchmarks: a UR3e at the origin, the
/// tracker across the room, the head in front of the robot, the coil on top of it.
pub mod scene {
    use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

    /// The tracker's pose in the robot base frame (`Y`).
    pub fn base_from_tracker() -> Isometry3<f64> {
        Isometry3::new(Vector3::new(1.2, 0.3, 0.4), Vector3::new(0.1, -0.2, 2.8))
    }

    /// The coil 5 cm below the flange, along the flange's z axis.
    pub fn flange_from_coil() -> Isometry3<f64> {
        Isometry3::translation(0.0, 0.0, 0.05)
    }

    /// On top of the head, 3 mm above the scalp (ellipsoid semi-axis 0.11 m), the coil's z axis
    /// pointing into the head.
    pub fn head_from_coil_goal() -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.113),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        )
    }

    /// The head at rest, in front of the UR3e (`base_from_head`).
    pub fn head_rest() -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(0.30, -0.12, -0.02),
            Vector3::new(0.0, 0.0, 0.3),
        )
    }
}

/// Panics unless this process's network namespace has no interface but loopback: DDS discovers
/// peers by multicast on every interface it finds, and test traffic must not leave the machine.
/// `scripts/test.sh` runs the tests in such a namespace (`unshare --net`, `lo` up with a multicast
/// route).
pub fn assert_loopback_only() {
    let dev = std::fs::read_to_string("/proc/net/dev").unwrap_or_default();
    let others: Vec<&str> = dev
        .lines()
        .skip(2)
        .filter_map(|l| l.split(':').next().map(str::trim))
        .filter(|name| *name != "lo")
        .collect();
    assert!(
        others.is_empty() && !dev.is_empty(),
        "this test speaks DDS, which discovers by multicast on every interface, and the network \
         here has {others:?} besides loopback: run it through scripts/test.sh, which runs the \
         tests in a network namespace with only `lo` (unshare --net; ip link set lo up; ip route \
         add 224.0.0.0/4 dev lo)"
    );
}
