//! Helpers shared by the CLI test files (each includes this with `mod common;`).
#![allow(dead_code)] // not every test file uses every helper

use std::process::{Command, Output};

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
