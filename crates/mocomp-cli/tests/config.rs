#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! One configuration for every command: `mocomp config print/check`, and the demo's printed
//! configuration run live by `mocomp run`, and `run`'s example run by the demo.

mod common;
use common::{assert_success, mocomp};
use mocomp_testkit::TempDir;

fn stdout(out: &std::process::Output) -> String {
    String::from_utf8(out.stdout.clone()).unwrap()
}

#[test]
fn config_print_gives_every_key_and_check_names_what_is_wrong() {
    let dir = TempDir::new("mocomp-config");
    // Every default, commented; it checks as the simulated world.
    let all = mocomp(&["config", "print"]);
    assert_success(&all);
    let text = stdout(&all);
    for key in [
        "[robot]",
        "simulate = true",
        "[experiment.paper]",
        "max_joint_accel_rad_s2 = 120.0",
    ] {
        assert!(text.contains(key), "{key}: {text}");
    }
    let path = dir.path("all.toml");
    std::fs::write(&path, &text).unwrap();
    let ok = mocomp(&["config", "check", &path]);
    assert_success(&ok);
    assert!(stdout(&ok).contains("ok (simulated ur3"), "{}", stdout(&ok));
    // A file's values, printed into the template; what the file does not set stays default.
    std::fs::write(&path, "[servo]\ngain = 900.0\n").unwrap();
    let p = mocomp(&["config", "print", "--config", &path]);
    assert_success(&p);
    assert!(stdout(&p).contains("gain = 900.0"), "{}", stdout(&p));
    assert!(stdout(&p).contains("lookahead_s = 0.03"));
    // A real robot without its coil mounting, a bad value: exit 2, the key named.
    for (file, key) in [
        (
            "[robot]\nsimulate = false\n",
            "calibration.flange_from_coil",
        ),
        (
            "[robot]\nsimulate = false\n[calibration]\nflange_from_coil = [0,0,0.05,0,0,0]\n[tracker]\nsource = \"openigtlink\"\nigtl = \"127.0.0.1:1\"\n[calibration.x]\n",
            "calibration.x",
        ),
        ("[loop]\nspeed_fraction = 0.0\n", "loop.speed_fraction"),
    ] {
        std::fs::write(&path, file).unwrap();
        let out = mocomp(&["config", "check", &path]);
        assert_eq!(out.status.code(), Some(2), "{file}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(key), "{file}: {err}");
    }
    // A real tracker without a goal: `run` needs one, and `check` says so.
    std::fs::write(
        &path,
        "[tracker]\nsource = \"openigtlink\"\nigtl = \"127.0.0.1:1\"\n[calibration]\nbase_from_tracker = [1,0,1,0,0,0]\n",
    )
    .unwrap();
    let out = mocomp(&["config", "check", &path]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("goal.head_from_coil"));
}

/// The two must-shows: the demo's printed configuration runs live, and the live example
/// runs the demo.
#[test]
fn the_demos_printed_configuration_runs_live_and_runs_example_runs_the_demo() {
    let dir = TempDir::new("mocomp-config-shared");
    let printed = mocomp(&["demo", "--print-config", "--coil-host", "127.0.91.2"]);
    assert_success(&printed);
    let path = dir.path("f.toml");
    std::fs::write(&path, stdout(&printed)).unwrap();
    let run = mocomp(&[
        "run",
        "--config",
        &path,
        "--seconds",
        "3",
        "--json",
        "--quiet",
    ]);
    assert_success(&run);
    let j: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    // A simulated UR3 at 125 Hz for 3 s, stopped at the end.
    let cycles = j["cycles"].as_u64().unwrap();
    assert!((300..=380).contains(&cycles), "{j}");
    assert_eq!(j["stop"]["outcome"], "standstill", "{j}");

    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/run-sim.toml");
    let out_dir = dir.path("demo");
    let demo = mocomp(&[
        "demo",
        "--config",
        example,
        "--seconds",
        "3",
        "--json",
        "--quiet",
        "--out",
        &out_dir,
        "--coil-host",
        "127.0.91.3",
        "--head-host",
        "127.0.91.4",
    ]);
    assert_success(&demo);
    let j: serde_json::Value = serde_json::from_slice(&demo.stdout).unwrap();
    // The file's robot (a UR3e, so a UR5e beside it) and motion.
    assert_eq!(j["coil_robot"], "ur3e", "{j}");
    assert_eq!(j["head_robot"], "ur5e", "{j}");
    assert_eq!(j["motion"], "nods", "{j}");
    // What the file sets that the experiment does not use is named, not ignored.
    let note = String::from_utf8_lossy(&demo.stderr);
    assert!(
        note.contains("does not use") && note.contains("goal"),
        "{note}"
    );
}
