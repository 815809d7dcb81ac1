//! Helpers shared by the CLI test files (each includes this with `mod common;`).
#![allow(dead_code)] // not every test file uses every helper

pub mod session;

use mocomp_testkit::{TempDir, workspace_root};
use std::process::{Command, Output};

/// `examples/run-sim.toml`'s text.
pub fn example() -> String {
    std::fs::read_to_string(workspace_root().join("examples/run-sim.toml")).unwrap()
}

/// Writes the example configuration to `dir`/run.toml with its simulated robot on `host` (each
/// test its own loopback address, so tests in parallel do not share the UR ports) and each
/// `(old, new)` line replaced; returns its path.
pub fn example_changed(dir: &TempDir, host: &str, changes: &[(&str, &str)]) -> String {
    let path = dir.path("run.toml");
    let mut cfg = example().replace("host = \"127.0.0.2\"", &format!("host = \"{host}\""));
    for (from, to) in changes {
        assert!(cfg.contains(from), "the example has no {from:?}");
        cfg = cfg.replace(from, to);
    }
    std::fs::write(&path, cfg).unwrap();
    path
}

/// Runs the `mocomp` binary with `args` and collects its output.
pub fn mocomp(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_mocomp"))
        .args(args)
        .output()
        .unwrap()
}

/// Asserts a zero exit, showing the exit status and stderr otherwise.
pub fn assert_success(out: &Output) {
    assert!(
        out.status.success(),
        "exit {:?}, stderr: {}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The arguments of `mocomp run --config CONFIG --seconds SECONDS --quiet --json`, then `extra`.
pub fn run_args<'a>(config: &'a str, seconds: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "run",
        "--config",
        config,
        "--seconds",
        seconds,
        "--quiet",
        "--json",
    ];
    args.extend_from_slice(extra);
    args
}
