//! Helpers shared by the CLI test files (each includes this with `mod common;`).
#![allow(dead_code)] // not every test file uses every helper

pub mod on_goal;
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

/// Whether a run's JSON summary `v` says the loop reached its goal: it tracked, as the run's own
/// judge (`NotReached`) counts it. Not the `Reached` event alone: an approach that a hold
/// interrupts (a state gone stale while a busy host paused the controller's virtual CPU) and
/// that resumes on the goal says `Resume`, and the coil is on its goal all the same.
pub fn reached(v: &serde_json::Value) -> bool {
    v["tracking_percent"].as_f64().is_some_and(|p| p > 0.0)
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

/// The pose of six numbers (x, y, z in m, a rotation vector in rad) at `key` of a JSON object.
pub fn pose_json(v: &serde_json::Value) -> mocomp_geom::nalgebra::Isometry3<f64> {
    let p: Vec<f64> = (0..6).map(|i| v[i].as_f64().unwrap()).collect();
    pose6(&p)
}

/// The pose of six numbers (x, y, z in m, a rotation vector in rad) in a TOML array.
pub fn pose_toml(v: &toml::Value) -> mocomp_geom::nalgebra::Isometry3<f64> {
    let p: Vec<f64> = (0..6).map(|i| v[i].as_float().unwrap()).collect();
    pose6(&p)
}

/// The pose of six numbers: x, y, z (m) and a rotation vector (rad).
pub fn pose6(p: &[f64]) -> mocomp_geom::nalgebra::Isometry3<f64> {
    use mocomp_geom::nalgebra::{Isometry3, Vector3};
    Isometry3::new(
        Vector3::new(p[0], p[1], p[2]),
        Vector3::new(p[3], p[4], p[5]),
    )
}

/// A pyigtl 0.3.4 server (required) on a free loopback port streaming `frames` (device → 4×4
/// mm) at `rate_hz` once a client connects; the peer (keep it alive) and its address.
pub fn pyigtl_streaming(
    frames: Vec<serde_json::Value>,
    rate_hz: f64,
) -> (mocomp_testkit::PythonPeer, String) {
    let mut py = mocomp_testkit::PythonPeer::start("pyigtl_peer.py", "pyigtl", "0.3.4");
    let port = py.request(&serde_json::json!({"op": "server", "port": 0}))["port"]
        .as_u64()
        .unwrap();
    py.request(&serde_json::json!({"op": "stream", "frames": frames, "rate_hz": rate_hz}));
    (py, format!("127.0.0.1:{port}"))
}

/// The rows of a 4×4 matrix, as JSON and OpenIGTLink peers take them.
pub fn rows4(m: &mocomp_geom::nalgebra::Matrix4<f64>) -> [[f64; 4]; 4] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]))
}

/// FreeSurfer's fsaverage scalp (MNE's, through the head peer) written to `dir`/fsaverage.ply,
/// and a configuration `dir`/nav.toml whose `[head]` is that scan (mm, `head_lines` added) with
/// MNE's fiducials and its 10-05 inion (Iz) as `[head.landmarks]` (the inion's key capitalised:
/// names match without regard to case). Returns the configuration's path and the fiducials,
/// `Iz` and `F3` (head frame = image frame, m).
pub fn fsaverage_config(
    dir: &TempDir,
    head_lines: &str,
) -> (
    String,
    std::collections::BTreeMap<String, mocomp_geom::nalgebra::Point3<f64>>,
) {
    use mocomp_geom::nalgebra::Point3;
    let mesh = dir.path("fsaverage.ply");
    mocomp_testkit::anatomy::write_fsaverage(&mesh, "ply");
    let (fid, eeg) = mocomp_testkit::anatomy::fsaverage_points("fsaverage_1005");
    let mm = |p: &Point3<f64>| format!("[{}, {}, {}]", p.x * 1e3, p.y * 1e3, p.z * 1e3);
    let config = dir.path("nav.toml");
    std::fs::write(
        &config,
        format!(
            "[head]\nmesh = \"fsaverage.ply\"\nunits = \"mm\"\n{head_lines}\n\
             [head.landmarks]\nnasion = {}\nInion = {}\nlpa = {}\nrpa = {}\n",
            mm(&fid["nasion"]),
            mm(&eeg["Iz"]),
            mm(&fid["lpa"]),
            mm(&fid["rpa"]),
        ),
    )
    .unwrap();
    let mut points = fid;
    points.insert("Iz".into(), eeg["Iz"]);
    points.insert("F3".into(), eeg["F3"]);
    (config, points)
}
