#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `mocomp run`: the example configuration runs the loop on the simulated UR3e and simulated
//! tracker (real RTDE and OpenIGTLink on loopback), writes its CSV and summary, and stops; bad
//! configurations are refused with the key named.

mod common;
use common::{assert_success, example, example_changed, mocomp, run_args};
use mocomp_testkit::TempDir;

/// The example configuration with its simulated robot on `host`; its path.
fn example_at(dir: &TempDir, host: &str) -> String {
    example_changed(dir, host, &[])
}

#[test]
fn the_example_config_compensates_on_the_simulated_robot() {
    let dir = TempDir::new("mocomp-run");
    let path = example_at(&dir, "127.0.0.41");
    let csv = dir.path("run.csv");
    let out = mocomp(&run_args(&path, "6", &["--log-csv", &csv]));
    assert_success(&out);
    // Standard output is the summary alone, one JSON object.
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // The planned approach reached the goal, then the loop tracked the nodding head (the rows
    // below). Not asserted: the mode at the very end, nor that no state went stale. A virtual
    // CPU the host pauses for 30 ms makes the state really stale, and holding then is right;
    // `scripts/stress.sh` measures how often that happens.
    let events = v["event_log"].as_array().unwrap();
    assert!(common::reached(&v), "{events:?}");
    // Late cycles, however late, never make a step the controller refuses; the simulated
    // controller says how near its setpoints came and what it did. However they landed, no
    // setpoint implied more than the joint's maximum speed: 1/1.2 of the speed the simulated
    // controller stops the arm for.
    assert_eq!(v["protective_stops"], 0, "{v}");
    let sim = &v["simulator"];
    let peak = sim["setpoint_peak_share"].as_f64().unwrap();
    assert!(peak > 0.05 && peak <= 1.0 / 1.2 + 1e-6, "{sim}");
    let sim_events = sim["events"].as_array().unwrap();
    assert!(
        sim_events[0][1]
            .as_str()
            .unwrap()
            .starts_with("mocomp control program started"),
        "{sim}"
    );
    assert!(v["realtime"].as_str().unwrap().contains("SCHED"), "{v}");
    // The stop as it happened: stopj sent and the arm still within the wait.
    assert_eq!(v["stop"]["outcome"], "standstill", "{v}");
    assert!(v["stop"]["after_s"].as_f64().unwrap() < 3.0, "{v}");
    assert!(v["log_error"].is_null(), "{v}");
    let mut reader = csv::Reader::from_path(&csv).unwrap();
    let header = reader.headers().unwrap().clone();
    assert_eq!(&header[0], "t_s");
    assert_eq!(&header[1], "mode");
    assert_eq!(&header[8], "deviation_mm");
    let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
    // Every cycle in the log. The controller's 3,000 cycles of the 6 s each answered (a cycle on
    // a new state), not answered (missed: a state skipped or never sent), or never run (its
    // clock gave up, as a simulator stopped by a busy machine does): a count, whatever the
    // machine's speed. The loop's cycles on a state already answered (none newer within its
    // patience) are its own, none of the controller's.
    let (cycles, repeated, missed, given_up) = (
        v["cycles"].as_u64().unwrap(),
        v["repeated_cycles"].as_u64().unwrap(),
        v["missed_cycles"].as_u64().unwrap(),
        sim["cycles_given_up"].as_u64().unwrap(),
    );
    assert_eq!(rows.len() as u64, cycles, "{v}");
    assert!(
        (cycles - repeated + missed + given_up).abs_diff(3000) <= 5,
        "{v}"
    );
    let tracking: Vec<_> = rows.iter().filter(|r| &r[1] == "tracking").collect();
    assert!(tracking.len() > 200, "{}", tracking.len());
    // The deviation while tracking stays within a centimetre, except while the coil catches up
    // after a hold, which must end within a second (judged apart: how far the head went while
    // the loop held depends on how long the machine held it up).
    common::on_goal::OnGoal::read(&csv, 5.0).check(10.0, 1.0, &v);
}

#[test]
fn contact_mode_on_the_simulated_scalp_holds_its_force_and_logs_it() {
    let dir = TempDir::new("mocomp-run-contact");
    // The example's e-Series arm and nodding head, pressing on the simulated scalp with a 3 N
    // set force after zeroing the sensor.
    let path = example_changed(
        &dir,
        "127.0.0.65",
        &[
            ("zero_force_sensor = false", "zero_force_sensor = true"),
            ("force_sensing = false", "force_sensing = true"),
            ("contact_mode = false", "contact_mode = true"),
        ],
    );
    let csv = dir.path("run.csv");
    let out = mocomp(&[
        "run",
        "--config",
        &path,
        "--seconds",
        "10",
        "--log-csv",
        &csv,
        "--json",
    ]);
    assert_success(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("force/torque sensor zeroed"), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["force_retreats"], 0, "{v}");
    // No protective stop, unless the machine stalled the robot's state first: the loop then
    // stops the arm (RobotStale is a fault), and the head nodding into a stopped coil on the
    // scalp reaches the controller's force limit. That is the simulated physics of a stall
    // (`scripts/stress.sh` counts stalls), not the admittance's doing.
    let stalled = v["robot_stale_holds"].as_u64().unwrap() > 0;
    assert!(stalled || v["protective_stops"] == 0, "{v}");
    let max = v["contact_force_n_max"].as_f64().unwrap();
    assert!(max > 2.0 && (stalled || max < 15.0), "{v}");
    // On the scalp while tracking in the last 6 s (from 4 s in, the approach done): the force
    // read stays near the set 3 N (the sensor's noise and the nods' tracking error around it).
    // How many of those cycles track is the machine's: one that holds the loop up holds the
    // coil too, and a hold takes its cycles; half a second of them is plenty for the figures.
    let mut reader = csv::Reader::from_path(&csv).unwrap();
    let header = reader.headers().unwrap().clone();
    let col = header.iter().position(|h| h == "contact_force_n").unwrap();
    let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
    let t_end: f64 = rows.last().unwrap()[0].parse().unwrap();
    let mut late: Vec<f64> = rows
        .iter()
        .filter(|r| &r[1] == "tracking" && r[0].parse::<f64>().unwrap() > t_end - 6.0)
        .map(|r| r[col].parse().unwrap())
        .collect();
    assert!(late.len() > 250, "{} cycles tracking: {v}", late.len());
    let mean = late.iter().sum::<f64>() / late.len() as f64;
    late.sort_by(f64::total_cmp);
    let p99 = late[late.len() * 99 / 100];
    assert!(
        (mean - 3.0).abs() < 0.5 && p99 < 8.0,
        "mean {mean} N, p99 {p99} N"
    );
}

#[test]
fn a_cb3_has_no_force_sensor_to_zero() {
    let dir = TempDir::new("mocomp-run-cb3-zero");
    let path = example_changed(
        &dir,
        "127.0.0.66",
        &[
            ("model = \"ur3e\"", "model = \"ur3\""),
            ("zero_force_sensor = false", "zero_force_sensor = true"),
        ],
    );
    let out = mocomp(&["run", "--config", &path, "--seconds", "1", "--quiet"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("robot.zero_force_sensor") && err.contains("CB3 has none"),
        "{err}"
    );
}

#[test]
fn a_log_that_cannot_be_written_fails_the_run_after_the_robot_is_stopped() {
    let dir = TempDir::new("mocomp-run-full");
    let path = example_at(&dir, "127.0.0.46");
    // /dev/full: every write fails with "no space left on device", like a full disk.
    let out = mocomp(&run_args(&path, "1", &["--log-csv", "/dev/full"]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("/dev/full") && err.contains("incomplete"),
        "{err}"
    );
    // The summary still came out, with the stop and the log's error in it.
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["stop"]["outcome"], "standstill", "{v}");
    assert!(
        v["log_error"]
            .as_str()
            .unwrap()
            .to_lowercase()
            .contains("space"),
        "{v}"
    );
}

#[test]
fn unknown_keys_and_out_of_range_values_are_refused_by_name() {
    let dir = TempDir::new("mocomp-run-bad");
    for (from, to, named) in [
        (
            "tracker_stale_s = 0.075",
            "tracker_stale = 0.075",
            "tracker_stale",
        ),
        (
            "speed_fraction = 0.75",
            "speed_fraction = 2.0",
            "speed_fraction",
        ),
        ("kind = \"nods\"", "kind = \"dance\"", "dance"),
        ("sway_m = 0.02", "swaym = 0.02", "swaym"),
        (
            "latency_s = 0.02",
            "latency_s = -1",
            "tracker.simulated.model.latency_s",
        ),
        ("poses = 15", "poses = 2", "calibrate.poses"),
        (
            "timestamps = \"auto\"",
            "timestamps = \"gps\"",
            "tracker.timestamps",
        ),
        ("gain = 2000.0", "gain = 5000.0", "servo.gain"),
        ("model = \"ur3e\"", "model = \"ur4\"", "robot.model"),
        (
            "radii_m = [0.075, 0.095, 0.11]",
            "radii_m = [0.075, -0.095, 0.11]",
            "head.radii_m[1]",
        ),
        ("cpu = 1 ", "cpu = 4096 ", "realtime.cpu"),
        (
            "simulator_priority = 49",
            "simulator_priority = 0",
            "realtime.simulator_priority",
        ),
        ("lock_memory = true", "lock_memry = true", "lock_memry"),
        // Choices are types: the key's path and the allowed values are named.
        (
            "source = \"simulated\"",
            "source = \"kinect\"",
            "tracker.source: TOML parse error at line",
        ),
        (
            "method = \"refined\"",
            "method = \"best\"",
            "calibrate.method",
        ),
        ("model = \"ur3e\"", "model = \"ur4\"", "known: ur3, ur5"),
        (
            "speed_fraction = 0.75",
            "speed_fraction = \"half\"",
            "loop.speed_fraction",
        ),
    ] {
        let cfg = example();
        assert!(cfg.contains(from), "{from}");
        let path = dir.path("bad.toml");
        std::fs::write(&path, cfg.replace(from, to)).unwrap();
        let out = mocomp(&["run", "--config", &path, "--seconds", "1"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{to}: {err}");
        assert!(
            err.contains(named) && err.contains("bad.toml"),
            "{to}: {err}"
        );
    }
    let out = mocomp(&["run", "--config", &dir.path("missing.toml")]);
    // A missing file is the user's argument: exit 2, the file named.
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("missing.toml"));
}

/// `[tracker.simulated.motion] kind = "file"`: the trace is read relative to the configuration's
/// directory and replayed; a missing or malformed one is refused with its name.
#[test]
fn the_run_replays_a_recorded_motion_relative_to_its_config() {
    let dir = TempDir::new("mocomp-run-trace");
    std::fs::write(
        dir.path("head.csv"),
        "t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,0,0,900,1,0,0,0\n0.5,5,0,900,1,0,0,0\n",
    )
    .unwrap();
    let motion = "kind = \"nods\"                  # sway and turn at frequency_hz, nod at 0.7 of it: peaks 89 mm/s, 34°/s";
    let cfg = example();
    assert!(cfg.contains(motion));
    let cfg = cfg
        .replace(motion, "kind = \"file\"\npath = \"head.csv\"")
        .replace("sway_m = 0.02 ", "# sway_m")
        .replace("turn_rad = 0.15 ", "# turn_rad")
        .replace("nod_rad = 0.08 ", "# nod_rad")
        .replace("frequency_hz = 0.6366 ", "# frequency_hz")
        .replace("host = \"127.0.0.2\"", "host = \"127.0.0.45\"");
    let path = dir.path("run.toml");
    std::fs::write(&path, &cfg).unwrap();
    let out = mocomp(&run_args(&path, "1", &[]));
    assert_success(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["cycles"].as_u64().unwrap() > 300, "{v}");

    std::fs::write(dir.path("run.toml"), cfg.replace("head.csv", "gone.csv")).unwrap();
    let out = mocomp(&["run", "--config", &path, "--seconds", "1"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("tracker.simulated.motion.path") && err.contains("gone.csv"),
        "{err}"
    );
}

#[test]
fn a_taken_robot_address_moves_the_simulated_robot_to_a_free_one_and_says_so() {
    let dir = TempDir::new("mocomp-run-taken");
    // Something else serves RTDE's port on the configured address.
    let _taken = std::net::TcpListener::bind("127.0.0.240:30004").unwrap();
    let path = example_at(&dir, "127.0.0.240");
    let out = mocomp(&["run", "--config", &path, "--seconds", "1", "--quiet"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert_success(&out);
    assert!(
        text.contains("on 127.0.0.241 (robot.host 127.0.0.240: its ports are taken)"),
        "{text}"
    );
}
