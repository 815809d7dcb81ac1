#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! `mocomp run` with a `[session]`: on the simulated world (a UR3e over RTDE, the tracker over
//! OpenIGTLink, both on loopback) the loop starts on a target of a grid made by `mocomp targets`,
//! the on-target gate drives the robot's output, the simulated stimulator wired through it pulses
//! the robot's input (or announces its pulses over OpenIGTLink), and the pulse log has a row per
//! pulse; a tracker that is not where the calibration says is caught by the drift monitor on the
//! flange marker, and the loop holds.

mod common;
use common::{assert_success, example_changed, mocomp, run_args};
use mocomp_testkit::TempDir;

/// The example configuration on `host`, the head nodding gently (a seated patient's, about
/// 8 mm/s), with `session` appended and each `(old, new)` line replaced.
fn config(dir: &TempDir, host: &str, session: &str, changes: &[(&str, &str)]) -> String {
    let mut all = vec![
        ("sway_m = 0.02 ", "sway_m = 0.004 "),
        ("turn_rad = 0.15 ", "turn_rad = 0.03 "),
        ("nod_rad = 0.08 ", "nod_rad = 0.02 "),
        ("frequency_hz = 0.6366 ", "frequency_hz = 0.3 "),
    ];
    all.extend_from_slice(changes);
    let path = example_changed(dir, host, &all);
    let mut cfg = std::fs::read_to_string(&path).unwrap();
    cfg.push_str(session);
    std::fs::write(&path, cfg).unwrap();
    path
}

/// A targets file with the hotspot (the example's goal) and the 3 × 3 grid around it.
fn targets(dir: &TempDir, config: &str) -> String {
    let file = dir.path("targets.toml");
    std::fs::write(
        &file,
        "[[target]]\nname = \"hot\"\nhead_from_coil = [0.0, 0.0, 0.113, 3.141592653589793, 0.0, 0.0]\n",
    )
    .unwrap();
    let out = mocomp(&[
        "targets", "--file", &file, "grid", "hot", "--config", config,
    ]);
    assert_success(&out);
    file
}

fn run(config: &str, seconds: &str) -> serde_json::Value {
    let out = mocomp(&run_args(config, seconds, &[]));
    assert_success(&out);
    serde_json::from_slice(&out.stdout).unwrap()
}

fn event_lines(v: &serde_json::Value) -> Vec<String> {
    v["event_log"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e[1].as_str().unwrap().to_string())
        .collect()
}

/// The pulse log's rows, read back as the exports read them.
fn pulse_rows(path: &str) -> Vec<mocomp_session::Pulse> {
    let text = std::fs::read_to_string(path).unwrap();
    assert_eq!(
        text.lines().next().unwrap().split(',').collect::<Vec<_>>(),
        mocomp_session::pulses::HEADER
    );
    mocomp_session::read_log(path, &text).unwrap()
}

/// Unix seconds now (the test's own clock, to bound the log's UTC times).
fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64()
}

/// Checks the run `v`'s pulse log `log`, written between `started` and `ended` (Unix s), with
/// the stimulator's output `output_pct`.
fn check_pulses(v: &serde_json::Value, log: &str, (started, ended): (f64, f64), output_pct: f64) {
    let rows = pulse_rows(log);
    let ses = &v["session"];
    eprintln!("{ses}");
    // A 5 Hz stimulator gated by the output, over the seconds on target.
    assert!(rows.len() >= 10, "{} pulses: {v}", rows.len());
    assert_eq!(ses["pulses"].as_u64().unwrap(), rows.len() as u64, "{v}");
    let open: Vec<_> = rows.iter().filter(|r| r.gate_open).collect();
    // A pulse the stimulator fired as the gate was shutting (it read the output a moment
    // before) is logged off target, as it was; such are rare.
    assert!(open.len() * 10 >= rows.len() * 9, "{rows:?}");
    // The target, from the targets file beside the log.
    let file = std::path::Path::new(log).with_file_name("targets.toml");
    let text = std::fs::read_to_string(&file).unwrap();
    let target = mocomp_session::Targets::parse("targets.toml", &text)
        .unwrap()
        .targets
        .iter()
        .find(|t| t.name == "hot-r0c1")
        .unwrap()
        .pose();
    let mut last_utc = f64::NEG_INFINITY;
    for r in &rows {
        assert_eq!(r.target, "hot-r0c1", "{r:?}");
        // Clock time, in order, within the run; the output the stimulator fired at.
        let utc = r.utc_unix_s.unwrap();
        assert!(
            utc > started && utc < ended && utc >= last_utc,
            "{r:?} {started} {ended}"
        );
        last_utc = utc;
        assert_eq!(r.output_pct, Some(output_pct), "{r:?}");
    }
    for r in open {
        let mm = r.position_error_m * 1e3;
        assert!(mm <= 2.0, "a pulse through an open gate {mm} mm off");
        // On the image (here the head marker's frame: the example has no registration) where
        // the target is, by the error the row gives; near the scalp the grid lies on.
        let coil = r
            .image_from_coil
            .expect("an open gate's pulse has the coil's pose");
        let d = (coil.translation.vector - target.translation.vector).norm();
        assert!((d - r.position_error_m).abs() < 1e-5, "{d} {r:?}");
        let a = coil.rotation.angle_to(&target.rotation);
        assert!((a - r.angle_error_rad).abs() < 1e-4, "{a} {r:?}");
        // The coil's face on the scalp's outside, as close as the grid's targets put it.
        let mm = r.scalp_distance_m * 1e3;
        assert!((-1.0..15.0).contains(&mm), "{mm} mm to the scalp: {r:?}");
    }
    assert!(ses["gate_openings"].as_u64().unwrap() >= 1, "{v}");
    let lines = event_lines(v);
    assert!(
        lines.iter().any(|l| l == "gate open on hot-r0c1"),
        "{lines:?}"
    );
    assert!(
        lines.iter().any(|l| l.starts_with("pulse on hot-r0c1")),
        "{lines:?}"
    );
    assert!(!ses["calibration_invalid"].as_bool().unwrap(), "{v}");
}

/// The example's ellipsoid head (semi-axes 75, 95, 110 mm about the head marker's origin, the
/// example's image frame) as a T1: 64³ voxels of 4 mm, 150 inside, 0 outside.
fn ellipsoid_t1(dir: &TempDir) -> String {
    let n = mocomp_testkit::nifti::Nifti::cube(64, 4.0, |p| {
        let r = (p[0] / 75.0).powi(2) + (p[1] / 95.0).powi(2) + (p[2] / 110.0).powi(2);
        if r < 1.0 { 150 } else { 0 }
    });
    let path = dir.path("t1.nii");
    std::fs::write(&path, n.bytes()).unwrap();
    path
}

/// The session's log `log` exported as BIDS and as Localite: every pulse a row at its time, the
/// NIBS files with the draft's columns, the BIDS core valid to the BIDS validator, the Localite
/// file read back by mocomp's importer to the logged poses.
fn export(dir: &TempDir, cfg: &str, log: &str) {
    let pulses = pulse_rows(log);
    let posed: Vec<_> = pulses.iter().filter_map(|p| p.image_from_coil).collect();
    assert!(!posed.is_empty());
    let bids = dir.path("bids");
    let t1 = ellipsoid_t1(dir);
    let out = mocomp(&[
        "session",
        "export",
        "--config",
        cfg,
        "--bids",
        &bids,
        "--t1",
        &t1,
        "--subject",
        "07",
        "--session",
        "2",
        "--task",
        "hotspot",
    ]);
    assert_success(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(
        said.starts_with(&format!(
            "{} pulses ({} with the coil's pose)",
            pulses.len(),
            posed.len()
        )),
        "{said}"
    );
    let table = |file: &str| -> (Vec<String>, Vec<Vec<String>>) {
        let text = std::fs::read_to_string(format!(
            "{bids}/sub-07/ses-2/nibs/sub-07_ses-2_stimsys-tms_{file}"
        ))
        .unwrap();
        let mut lines = text.lines();
        let head = lines
            .next()
            .unwrap()
            .split('\t')
            .map(String::from)
            .collect();
        (
            head,
            lines
                .map(|l| l.split('\t').map(String::from).collect())
                .collect(),
        )
    };
    // The draft's columns (nibs-bids-v5+, "2. prefrontal-tms-eeg": *_nibs.tsv, *_markers.tsv).
    let (head, rows) = table("task-hotspot_nibs.tsv");
    for c in [
        "CoilDriver",
        "CoilID",
        "StimulusMode",
        "MarkerID",
        "StimStepCount",
        "FirstPulseAmplitude",
        "StimValidation",
        "Timestamp",
    ] {
        assert!(head.iter().any(|h| h == c), "{c} not in {head:?}");
    }
    let col = |h: &[String], n: &str| h.iter().position(|x| x == n).unwrap();
    assert_eq!(rows.len(), pulses.len(), "every pulse a row");
    for (r, p) in rows.iter().zip(&pulses) {
        assert_eq!(r.len(), head.len(), "{r:?}");
        assert_eq!(
            r[col(&head, "Timestamp")],
            mocomp_session::iso8601(p.utc_unix_s.unwrap())
        );
        assert_eq!(r[col(&head, "TargetName")], p.target);
        assert_eq!(r[col(&head, "FirstPulseAmplitude")], "60.0");
        assert_eq!(
            r[col(&head, "StimValidation")],
            if p.gate_open { "OK" } else { "OffTarget" }
        );
    }
    let (mhead, markers) = table("task-hotspot_markers.tsv");
    for c in [
        "MarkerID",
        "coil_x",
        "coil_y",
        "coil_z",
        "normal_x",
        "normal_y",
        "normal_z",
        "direction_x",
        "direction_y",
        "direction_z",
        "Timestamp",
    ] {
        assert!(mhead.iter().any(|h| h == c), "{c} not in {mhead:?}");
    }
    assert_eq!(markers.len(), posed.len());
    for (m, pose) in markers.iter().zip(&posed) {
        let mm = pose.translation.vector * 1e3;
        for (c, v) in ["coil_x", "coil_y", "coil_z"]
            .iter()
            .zip([mm.x, mm.y, mm.z])
        {
            let got: f64 = m[col(&mhead, c)].parse().unwrap();
            assert!((got - v).abs() < 1e-3, "{c} {got} {v}");
        }
        // The normal is the coil's z, into the head.
        let z = pose.rotation * mocomp_geom::nalgebra::Vector3::z();
        let got: f64 = m[col(&mhead, "normal_z")].parse().unwrap();
        assert!((got - z.z).abs() < 1e-5, "{got} {z}");
    }
    // The BIDS core, by the BIDS validator (npm's bids-validator; scripts/test.sh installs it).
    let validator = std::env::var("MOCOMP_BIDS_VALIDATOR").unwrap_or_else(|_| {
        panic!(
            "MOCOMP_BIDS_VALIDATOR is not set: the BIDS validator (scripts/test.sh installs it \
             with `npm ci --prefix interop/bids`)"
        )
    });
    let checked = std::process::Command::new(&validator)
        .args([bids.as_str(), "--json"])
        .output()
        .unwrap_or_else(|e| panic!("{validator}: {e} (scripts/test.sh installs it)"));
    let report: serde_json::Value = serde_json::from_slice(&checked.stdout).unwrap_or_else(|e| {
        panic!(
            "{e}: {}{}",
            String::from_utf8_lossy(&checked.stdout),
            String::from_utf8_lossy(&checked.stderr)
        )
    });
    assert_eq!(
        report["issues"]["errors"],
        serde_json::json!([]),
        "{report}"
    );
    assert!(checked.status.success(), "{report}");
    let summary = &report["summary"];
    assert_eq!(summary["subjects"], serde_json::json!(["07"]), "{report}");
    assert_eq!(summary["sessions"], serde_json::json!(["2"]), "{report}");
    assert_eq!(summary["dataTypes"], serde_json::json!(["T1w"]), "{report}");
    // Localite, read back by mocomp's own importer: the logged poses, in order.
    let xml = dir.path("TriggerMarkers_Coil0_mocomp.xml");
    let out = mocomp(&["session", "export", "--config", cfg, "--localite", &xml]);
    assert_success(&out);
    let text = std::fs::read_to_string(&xml).unwrap();
    assert_eq!(text.matches("<TriggerMarker ").count(), pulses.len());
    let back =
        mocomp_navfiles::read::parse_poses(mocomp_navfiles::read::Navigator::Localite, &xml, &text)
            .unwrap();
    assert_eq!(back.len(), posed.len());
    for (b, pose) in back.iter().zip(&posed) {
        assert_eq!(b.name, "hot-r0c1");
        let d = (b.image_from_coil.translation.vector - pose.translation.vector).norm();
        assert!(d < 1e-9, "{d}");
        assert!(b.image_from_coil.rotation.angle_to(&pose.rotation) < 1e-6);
    }
    // The report: a row per pulse, the shut ones marked, the two figures.
    let html = dir.path("report.html");
    let out = mocomp(&["session", "report", "--config", cfg, "--out", &html]);
    assert_success(&out);
    let page = std::fs::read_to_string(&html).unwrap();
    assert_eq!(page.matches("<tr class=\"pulse").count(), pulses.len());
    assert_eq!(
        page.matches("<tr class=\"pulse shut\">").count(),
        pulses.iter().filter(|p| !p.gate_open).count()
    );
    assert_eq!(page.matches("<svg").count(), 2);
}

#[test]
fn a_session_starts_on_a_grid_target_and_logs_each_pulse_through_the_gate() {
    let dir = TempDir::new("mocomp-session");
    let pulses = dir.path("pulses.csv");
    let session = format!(
        "\n[session]\ntargets = \"targets.toml\"\ntarget = \"hot-r0c1\"\npulse_log = \"{pulses}\"\n\
         gate_output = 7\npulse_input = 0\nmarker_device = \"MarkerToTracker\"\n\
         stimulator_output_pct = 60.0\n[session.simulated_stimulator]\nrate_hz = 5.0\n"
    );
    let cfg = config(&dir, "127.0.0.73", &session, &[]);
    targets(&dir, &cfg);
    let started = unix_now();
    let v = run(&cfg, "10");
    let ended = unix_now();
    // The planned approach reached the target; the drift monitor on the flange marker saw an
    // exact calibration.
    assert!(common::reached(&v), "{v}");
    check_pulses(&v, &pulses, (started, ended), 60.0);
    // A robot input says nothing of the stimulator's own time.
    assert!(
        pulse_rows(&pulses)
            .iter()
            .all(|r| r.stimulator_unix_s.is_none())
    );
    export(&dir, &cfg, &pulses);
}

#[test]
fn pulses_announced_over_openigtlink_are_logged_alike() {
    let dir = TempDir::new("mocomp-session-igtl");
    let pulses = dir.path("pulses.csv");
    let session = format!(
        "\n[session]\ntargets = \"targets.toml\"\ntarget = \"hot-r0c1\"\npulse_log = \"{pulses}\"\n\
         gate_output = 7\nigtl_device = \"MocompGate\"\nstimulator_output_pct = 60.0\n\
         [session.simulated_stimulator]\nrate_hz = 5.0\noutput_pct = 65.0\n"
    );
    let cfg = config(&dir, "127.0.0.74", &session, &[]);
    targets(&dir, &cfg);
    let started = unix_now();
    let v = run(&cfg, "10");
    let ended = unix_now();
    // The stimulator says its output in each message (over the configured one) and stamps it
    // with its own clock, which is this machine's here: within the run, before it was received.
    check_pulses(&v, &pulses, (started, ended), 65.0);
    for r in pulse_rows(&pulses) {
        let own = r.stimulator_unix_s.expect("the stimulator's time");
        assert!(
            own > started && own <= r.utc_unix_s.unwrap() + 0.05,
            "{r:?}"
        );
    }
}

#[test]
fn a_tracker_that_moved_since_the_calibration_holds_the_loop() {
    let dir = TempDir::new("mocomp-session-drift");
    // The tracker truly stands 3 mm off where the calibration puts it.
    let cfg = config(
        &dir,
        "127.0.0.75",
        "\n[session]\nmarker_device = \"MarkerToTracker\"\n",
        &[(
            "# base_from_tracker = [1.0, 0.1, 0.9, 2.0019, -1.4693, -0.5718]",
            "base_from_tracker = [1.003, 0.1, 0.9, 2.0019, -1.4693, -0.5718]",
        )],
    );
    // Held before the coil came near the head, for the whole run: the run fails, saying why
    // (its summary printed first).
    let out = mocomp(&run_args(&cfg, "4", &[]));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("never reached its goal") && err.contains("calibration no longer valid"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        v["not_reached"]["code"]
            .as_str()
            .map(|c| c.starts_with("CalibrationInvalid(")),
        Some(true),
        "{v}"
    );
    let lines = event_lines(&v);
    assert!(
        v["session"]["calibration_invalid"].as_bool().unwrap(),
        "{v}"
    );
    // The offset measured: the filtered 3 mm (the monitor calls it at its 2 mm limit already).
    let said = lines
        .iter()
        .find_map(|l| l.strip_prefix("calibration no longer valid (tracker or base moved): "))
        .expect("the drift monitor's event");
    let mm: f64 = said.split(' ').next().unwrap().parse().unwrap();
    assert!((2.0..3.5).contains(&mm), "{said}");
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("Hold(CalibrationInvalid(")),
        "{lines:?}"
    );
    assert!(
        v["final_mode"]
            .as_str()
            .unwrap()
            .starts_with("holding (CalibrationInvalid("),
        "{v}"
    );
    // Held before the coil came near the head: never tracking.
    assert_eq!(v["tracking_percent"].as_f64().unwrap(), 0.0, "{v}");
}

#[test]
fn a_session_target_that_is_not_in_its_file_is_refused_by_name() {
    let dir = TempDir::new("mocomp-session-bad");
    let cfg = config(
        &dir,
        "127.0.0.76",
        "\n[session]\ntargets = \"targets.toml\"\ntarget = \"nowhere\"\n",
        &[],
    );
    targets(&dir, &cfg);
    let out = mocomp(&["run", "--config", &cfg, "--seconds", "1"]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("session.target \"nowhere\"") && err.contains("hot-r0c1"),
        "{err}"
    );
    let cfg = config(&dir, "127.0.0.76", "\n[session]\ngate_output = 16\n", &[]);
    let out = mocomp(&["run", "--config", &cfg, "--seconds", "1"]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("session.gate_output = 16"), "{err}");
}

/// With `[coil] model` (SimNIBS's Magstim D70 at 60 % output): every cycle's log has the dose
/// the measured coil gives at the selected target's brain point against that target's plan,
/// every pulse carries it, the run's summary scores it, and the gate with
/// `max_dose_error_pct` lets no pulse through further off its planned dose.
#[test]
fn with_a_coil_model_each_cycle_and_pulse_has_its_dose_and_the_gate_judges_it() {
    let dir = TempDir::new("mocomp-session-dose");
    let pulses = dir.path("pulses.csv");
    let cycles = dir.path("cycles.csv");
    let model = mocomp_testkit::workspace_root()
        .join("crates/mocomp-efield/tests/data/coils/MagStim_D70.ccd")
        .display()
        .to_string();
    let limit = 1.0;
    let session = format!(
        "\n[session]\ntargets = \"targets.toml\"\ntarget = \"hot-r0c1\"\npulse_log = \"{pulses}\"\n\
         gate_output = 7\npulse_input = 0\nstimulator_output_pct = 60.0\n\
         [session.gate]\nmax_dose_error_pct = {limit}\n\
         [session.simulated_stimulator]\nrate_hz = 5.0\n"
    );
    let coil = format!("thickness_m = 0.03\nmodel = {model:?}\noutput_pct = 60.0\n");
    let cfg = config(
        &dir,
        "127.0.0.87",
        &session,
        &[("thickness_m = 0.03\n", &coil)],
    );
    targets(&dir, &cfg);
    let out = mocomp(&run_args(&cfg, "10", &["--log-csv", &cycles]));
    assert_success(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(common::reached(&v), "{v}");
    // Each cycle tracking the target has a dose, against the target's own plan: near its
    // planned dose (the coil follows within a fraction of a millimetre; against another
    // target's plan, 20 mm away on the grid, it would be tens of percent off).
    let text = std::fs::read_to_string(&cycles).unwrap();
    let mut csv = csv::Reader::from_reader(text.as_bytes());
    let head = csv.headers().unwrap().clone();
    let col = |name: &str| head.iter().position(|h| h == name).unwrap();
    let (mode, pct, vm) = (col("mode"), col("dose_pct"), col("dose_v_per_m"));
    let mut tracked = Vec::new();
    for row in csv.records().map(Result::unwrap) {
        if &row[mode] == "tracking" {
            let p: f64 = row[pct].parse().unwrap();
            let e: f64 = row[vm].parse().unwrap();
            assert!((90.0..110.0).contains(&p), "{p} % while tracking");
            assert!(
                (20.0..400.0).contains(&e),
                "{e} V/m at 15 mm under the scalp"
            );
            tracked.push((p - 100.0).abs());
        }
    }
    assert!(tracked.len() > 500, "{} cycles tracking", tracked.len());
    // The summary's score is the log's.
    tracked.sort_by(f64::total_cmp);
    let max = tracked[tracked.len() - 1];
    let reported = v["dose_error_pct_max"].as_f64().unwrap();
    assert!((reported - max).abs() < 1e-2, "{reported} {max}");
    assert!(v["dose_error_pct_p95"].as_f64().unwrap() <= reported);
    // Each pulse has the dose of its cycle; through the open gate, within the limit.
    let rows = pulse_rows(&pulses);
    assert!(rows.len() >= 5, "{} pulses: {v}", rows.len());
    let open: Vec<_> = rows.iter().filter(|r| r.gate_open).collect();
    assert!(!open.is_empty(), "no pulse through the gate: {rows:?}");
    for r in &rows {
        assert!(r.dose_pct.is_finite() && r.dose_v_per_m > 0.0, "{r:?}");
    }
    for r in &open {
        assert!((r.dose_pct - 100.0).abs() <= limit, "{r:?}");
    }
    eprintln!(
        "dose error while tracking: RMS {} p95 {} max {} %; {} pulses, {} through the gate; {}",
        v["dose_error_pct_rms"],
        v["dose_error_pct_p95"],
        v["dose_error_pct_max"],
        rows.len(),
        open.len(),
        v["session"]
    );
    let worst = v["session"]["pulse_dose_error_max_pct"].as_f64().unwrap();
    assert!(worst <= limit, "{worst}");
    // A pulse the stimulator fired on a dose the gate refused says so.
    for r in rows
        .iter()
        .filter(|r| !r.gate_open && r.why_shut.starts_with("dose"))
    {
        assert!((r.dose_pct - 100.0).abs() > limit, "{r:?}");
    }
}

#[test]
fn a_gate_on_the_dose_without_a_coil_model_is_refused_by_name() {
    let dir = TempDir::new("mocomp-session-dose-none");
    let session = "\n[session.gate]\nmax_dose_error_pct = 5.0\n";
    let cfg = config(&dir, "127.0.0.88", session, &[]);
    let out = mocomp(&run_args(&cfg, "1", &[]));
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("session.gate.max_dose_error_pct") && err.contains("coil.model"),
        "{err}"
    );
}
