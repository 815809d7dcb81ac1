#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `mocomp demo`, short: the experiment runs end to end from the command line, writes its CSV and
//! summary, and its JSON shows mocomp beating the paper's pipeline by the margins.

mod common;
use common::{assert_success, mocomp};
use mocomp_testkit::TempDir;

/// `mocomp demo --json --quiet` into `out_dir` for `seconds`, the robots on `hosts` (each test
/// its own), with `extra` options.
fn demo_json(
    out_dir: &str,
    seconds: &str,
    hosts: (&str, &str),
    extra: &[&str],
) -> std::process::Output {
    let mut args = vec![
        "demo",
        "--out",
        out_dir,
        "--seconds",
        seconds,
        "--json",
        "--quiet",
        "--coil-host",
        hosts.0,
        "--head-host",
        hosts.1,
    ];
    args.extend_from_slice(extra);
    mocomp(&args)
}

#[test]
fn the_demo_writes_its_report_and_mocomp_wins() {
    let dir = TempDir::new("mocomp-demo");
    let out_dir = dir.path("out");
    let out = demo_json(&out_dir, "10", ("127.0.0.55", "127.0.0.56"), &[]);
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = j["controllers"].as_array().unwrap();
    assert_eq!(rows[0]["controller"], "paper");
    assert_eq!(rows[1]["controller"], "mocomp");
    assert!(j["ratio_d_max"].as_f64().unwrap() >= 10.0, "{j}");
    assert!(rows[1]["translation_mm_rms"].as_f64().unwrap() < 0.5, "{j}");
    // mocomp's true coil never enters the head model.
    assert_eq!(rows[1]["inside_head_s"].as_f64().unwrap(), 0.0, "{j}");
    assert!(rows[1]["min_clearance_mm"].as_f64().unwrap() > 0.0, "{j}");
    // The configuration it ran with is written beside the report.
    let cfg = std::fs::read_to_string(format!("{out_dir}/config.toml")).unwrap();
    assert!(
        cfg.contains("duration_s = 10.0") && cfg.contains("host = \"127.0.0.55\""),
        "{cfg}"
    );
    let csv = std::fs::read_to_string(format!("{out_dir}/demo.csv")).unwrap();
    // 10 s at 125 Hz, two controllers, and a header.
    assert_eq!(csv.lines().count(), 2 * 1250 + 1);
    // The figures: each a 1100×700 PNG and an SVG.
    for name in ["d", "errors", "head_speed", "latency", "contact", "events"] {
        let png = image::open(format!("{out_dir}/{name}.png"))
            .unwrap()
            .to_rgb8();
        assert_eq!(png.dimensions(), (1100, 700), "{name}.png");
        let svg = std::fs::read_to_string(format!("{out_dir}/{name}.svg")).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
            "{name}.svg"
        );
    }
    // d(t) draws every tick of both controllers, in their colours, twice (linear and log).
    let svg = std::fs::read_to_string(format!("{out_dir}/d.svg")).unwrap();
    for colour in ["#D62728", "#1F77B4"] {
        let lines: Vec<usize> = svg
            .split("<polyline")
            .skip(1)
            .filter(|p| p.contains(&format!("stroke=\"{colour}\"")))
            .map(|p| {
                let pts = p.split("points=\"").nth(1).unwrap();
                pts[..pts.find('"').unwrap()].split_whitespace().count()
            })
            .filter(|&n| n > 2)
            .collect();
        assert_eq!(lines, vec![1250, 1250], "{colour}");
    }
    let png = image::open(format!("{out_dir}/d.png")).unwrap().to_rgb8();
    for rgb in [[214, 39, 40], [31, 119, 180]] {
        let n = png.pixels().filter(|p| p.0 == rgb).count();
        assert!(n > 1000, "{rgb:?}: {n} pixels");
    }
    let md = std::fs::read_to_string(format!("{out_dir}/summary.md")).unwrap();
    assert!(
        md.contains("| mocomp |") && md.contains("| paper |"),
        "{md}"
    );
}

#[test]
fn the_demo_on_the_scalp_holds_a_light_contact_which_the_papers_pipeline_cannot() {
    let dir = TempDir::new("mocomp-demo-contact");
    let out_dir = dir.path("out");
    let out = demo_json(
        &out_dir,
        "8",
        ("127.0.0.63", "127.0.0.64"),
        &["--contact", "--motion", "nods"],
    );
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = j["controllers"].as_array().unwrap();
    let f = |row: usize, key: &str| rows[row][key].as_f64().unwrap();
    // mocomp holds loop.contact_force_n (3 N) by its admittance: RMS near it, never near the
    // limit, no force rule fired.
    assert!(
        (f(1, "contact_force_n_rms") - 3.0).abs() < 0.5,
        "mocomp: {}",
        rows[1]
    );
    assert!(f(1, "contact_force_n_max") < 15.0, "mocomp: {}", rows[1]);
    assert_eq!(f(1, "retreats"), 0.0, "{}", rows[1]);
    // The paper's pipeline, on the same touching goal, lags the nods and loses the scalp.
    assert!(f(0, "contact_force_n_rms") < 1.5, "paper: {}", rows[0]);
    // demo.csv has the force of every tick.
    let csv = std::fs::read_to_string(format!("{out_dir}/demo.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = header.iter().position(|h| *h == "contact_force_n").unwrap();
    let mocomp_forces: Vec<f64> = csv
        .lines()
        .filter(|l| l.starts_with("mocomp,"))
        .map(|l| l.split(',').nth(col).unwrap().parse().unwrap())
        .collect();
    assert_eq!(mocomp_forces.len(), 1000);
    let max = mocomp_forces.iter().copied().fold(0.0, f64::max);
    assert!((max - f(1, "contact_force_n_max")).abs() < 1e-3, "{max}");
}

#[test]
fn a_tracker_bumped_mid_run_is_seen_by_the_drift_monitor_within_half_a_second() {
    let dir = TempDir::new("mocomp-demo-bump");
    let out_dir = dir.path("out");
    let out = demo_json(
        &out_dir,
        "6",
        ("127.0.0.67", "127.0.0.68"),
        &[
            "--tracker-bump-at-s",
            "3",
            "--tracker-bump-mm",
            "3",
            "--tracker-bump-deg",
            "1",
        ],
    );
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for row in j["controllers"].as_array().unwrap() {
        let after = row["tracker_bump_detected_s"].as_f64().unwrap();
        assert!(after > 0.0 && after < 0.5, "{row}");
        // mocomp's loop holds on it ("calibration no longer valid"; a held coil still gives
        // way to the nodding head, which shows as a retreat and a second hold); the paper's
        // pipeline has no supervisor to hold (`mocomp-app`'s session test checks the reason).
        let holds = row["holds"].as_u64().unwrap();
        match row["controller"].as_str().unwrap() {
            "mocomp" => assert!(holds >= 1, "{row}"),
            _ => assert_eq!(holds, 0, "{row}"),
        }
    }
    // Before the bump the monitor said nothing: the calibration held.
    let csv = std::fs::read_to_string(format!("{out_dir}/demo.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let (t, drift) = (
        header.iter().position(|h| *h == "t_s").unwrap(),
        header.iter().position(|h| *h == "drift").unwrap(),
    );
    let mut changes = csv.lines().skip(1).filter_map(|l| {
        let f: Vec<&str> = l.split(',').collect();
        (!f[drift].is_empty()).then(|| f[t].parse::<f64>().unwrap())
    });
    assert!(
        changes.all(|at| at >= 3.0),
        "a drift verdict before the bump"
    );
    // A bump outside the run is refused, naming the option.
    let bad = demo_json(
        &out_dir,
        "6",
        ("127.0.0.67", "127.0.0.68"),
        &["--tracker-bump-at-s", "9"],
    );
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--tracker-bump-at-s"));
}

fn stdout(out: &std::process::Output) -> String {
    String::from_utf8(out.stdout.clone()).unwrap()
}

#[test]
fn the_config_file_and_the_options_set_the_experiment() {
    let dir = TempDir::new("mocomp-demo-config");
    // Options over the defaults, printed as a file; the file reads back to the same settings.
    let printed = mocomp(&[
        "demo",
        "--print-config",
        "--motion",
        "drift",
        "--speed-mm-s",
        "8",
        "--seconds",
        "4",
        "--tracker-noise-mm",
        "0.2",
        "--coil-host",
        "127.0.0.57",
        "--head-host",
        "127.0.0.58",
    ]);
    assert_success(&printed);
    let text = stdout(&printed);
    assert!(
        text.contains("kind = \"drift\"") && text.contains("noise_m = 0.0002"),
        "{text}"
    );
    let path = dir.path("demo.toml");
    std::fs::write(&path, &text).unwrap();
    let again = mocomp(&["demo", "--print-config", "--config", &path]);
    assert_success(&again);
    assert_eq!(stdout(&again), text);
    // A run from the file does what it says.
    let out_dir = dir.path("out");
    let run = mocomp(&[
        "demo", "--config", &path, "--json", "--quiet", "--out", &out_dir,
    ]);
    assert_success(&run);
    let j: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
    assert_eq!(j["motion"], "drift", "{j}");
    assert_eq!(j["seconds"], 4.0, "{j}");
    assert!(
        (j["tracker_noise_mm"].as_f64().unwrap() - 0.2).abs() < 1e-12,
        "{j}"
    );
    // The drift moves at the speed asked for.
    assert!(
        (j["head_peak_mm_s"].as_f64().unwrap() - 8.0).abs() < 0.05,
        "{j}"
    );
    // The example file is valid.
    let example = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/demo-nods.toml");
    let ex = mocomp(&["demo", "--print-config", "--config", example]);
    assert_success(&ex);
    assert!(stdout(&ex).contains("kind = \"nods\""));
}

#[test]
fn bad_settings_are_refused_naming_the_key_or_option() {
    let dir = TempDir::new("mocomp-demo-bad");
    let path = dir.path("bad.toml");
    let cases: [(&str, &[&str], &str); 6] = [
        (
            "duration_s = 3\n\n[tracker]\nnoise = 1\n",
            &[],
            "tracker.noise",
        ),
        (
            "[experiment]\nhead_robot = \"ur5e\"\n",
            &[],
            "experiment.head_robot",
        ),
        (
            "[tracker.simulated.motion]\nkind = \"nods\"\nsway_m = -1.0\n",
            &[],
            "tracker.simulated.motion.sway_m",
        ),
        (
            "",
            &["--motion", "still", "--speed-mm-s", "5"],
            "--speed-mm-s",
        ),
        (
            "",
            &["--tracker-rate-hz", "0"],
            "tracker.simulated.model.rate_hz",
        ),
        ("", &["--seconds=-2"], "experiment.duration_s"),
    ];
    for (file, opts, named) in cases {
        std::fs::write(&path, file).unwrap();
        let mut args = vec!["demo", "--print-config", "--config", &path];
        args.extend_from_slice(opts);
        let out = mocomp(&args);
        assert_eq!(out.status.code(), Some(2), "{file:?} {opts:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(named), "{file:?} {opts:?}: {err}");
        assert!(out.stdout.is_empty());
    }
}

/// `--controllers mocomp,oracle`: the oracle's row beside mocomp's, mocomp's excess over it and
/// both runs' split into the prediction's and the execution's share, in the JSON and the CSV;
/// a controller named twice or unknown is refused by name.
#[test]
fn the_oracle_runs_beside_mocomp_and_its_excess_and_split_are_reported() {
    let dir = TempDir::new("mocomp-demo-oracle");
    let out_dir = dir.path("out");
    let out = demo_json(
        &out_dir,
        "4",
        ("127.0.0.144", "127.0.0.145"),
        &["--motion", "nods", "--controllers", "mocomp,oracle"],
    );
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = j["controllers"].as_array().unwrap();
    assert_eq!(rows.len(), 2, "{j}");
    assert_eq!(
        (
            rows[0]["controller"].as_str(),
            rows[1]["controller"].as_str()
        ),
        (Some("mocomp"), Some("oracle"))
    );
    let excess = &rows[0]["excess_over_oracle"];
    let d = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap();
    assert!(
        (d(excess, "d_rms") - (d(&rows[0], "d_rms") - d(&rows[1], "d_rms"))).abs() < 1e-9,
        "{j}"
    );
    assert!(d(excess, "d_rms") > 0.0, "{j}");
    assert!(rows[1]["excess_over_oracle"].is_null(), "{j}");
    // Without a coil model, no dose.
    assert!(rows[0].get("dose_error_pct_rms").is_none(), "{j}");
    assert!(j["ratio_d_rms"].is_null(), "no paper, no ratio: {j}");
    for r in rows {
        assert!(
            d(&r["prediction_mm"], "rms").is_finite() && d(&r["execution_mm"], "rms").is_finite(),
            "{j}"
        );
    }
    assert!(d(&rows[1]["prediction_mm"], "rms") < 0.01, "{j}");
    let csv = std::fs::read_to_string(format!("{out_dir}/demo.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(
        header.ends_with(",prediction_mm,execution_mm,standoff_mm"),
        "{header}"
    );
    assert_eq!(
        csv.lines().filter(|l| l.starts_with("oracle,")).count(),
        500
    );
    for (opts, named) in [
        ("mocomp,mocomp", "mocomp named twice"),
        ("mocomp,pilot", "one of paper, mocomp, oracle"),
    ] {
        let out = mocomp(&["demo", "--print-config", "--controllers", opts]);
        assert_eq!(out.status.code(), Some(2), "{opts}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(named), "{opts}: {err}");
    }
}

/// A recorded motion replayed: irregular samples of a 30 mm/s sway with a turn, the head at rest
/// before it; the demo reports the trace's speeds and writes the file's path into its config.
#[test]
fn the_demo_replays_a_recorded_motion_file() {
    let dir = TempDir::new("mocomp-demo-trace");
    let trace = dir.path("head.csv");
    let mut text = String::from("# a recorded head: 10 mm sway at 3 rad/s, a 0.1 rad turn\n");
    text += "t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz\n";
    let mut t = 0.0f64;
    let mut k = 0u32;
    while t < 4.0 {
        let yaw = 0.05 * (2.0 * t).sin();
        text += &format!(
            "{:.4},{:.5},-20.5,950,{:.9},0,0,{:.9}\n",
            100.0 + t,
            10.0 * (3.0 * t).sin(),
            (yaw / 2.0).cos(),
            (yaw / 2.0).sin()
        );
        // Irregular, about 33 Hz.
        t += if k.is_multiple_of(3) { 0.021 } else { 0.035 };
        k += 1;
    }
    std::fs::write(&trace, text).unwrap();
    let out_dir = dir.path("out");
    let out = demo_json(
        &out_dir,
        "4",
        ("127.0.0.59", "127.0.0.60"),
        &["--motion-file", &trace],
    );
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["motion"], "file", "{j}");
    let v = j["head_peak_mm_s"].as_f64().unwrap();
    assert!((27.0..33.0).contains(&v), "the trace's 30 mm/s peak: {v}");
    let rows = j["controllers"].as_array().unwrap();
    assert_eq!(rows[1]["inside_head_s"].as_f64().unwrap(), 0.0, "{j}");
    let cfg = std::fs::read_to_string(format!("{out_dir}/config.toml")).unwrap();
    assert!(
        cfg.contains("kind = \"file\"") && cfg.contains("head.csv"),
        "{cfg}"
    );

    // A malformed trace: exit 2, the file, line and column named.
    std::fs::write(
        &trace,
        "t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz\n0,0,0,0,1,0,0,0\n0.1,0,abc,0,1,0,0,0\n",
    )
    .unwrap();
    let out = mocomp(&["demo", "--motion-file", &trace, "--quiet"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("head.csv") && err.contains("line 3, column y_mm"),
        "{err}"
    );
}

#[test]
fn the_same_options_give_the_same_csv_byte_for_byte() {
    // The experiment runs in lockstep on a stepped clock: nothing the machine does (how long
    // the simulators took to connect, how busy the cores are) may change a bit of the result.
    let dir = TempDir::new("mocomp-demo-same");
    let (a, b) = (dir.path("a"), dir.path("b"));
    let extra = ["--motion", "nods", "--tracker-dropouts-per-s", "1"];
    for out in [&a, &b] {
        let o = demo_json(out, "4", ("127.0.0.61", "127.0.0.62"), &extra);
        assert_success(&o);
    }
    let read = |d: &str| std::fs::read(std::path::Path::new(d).join("demo.csv")).unwrap();
    let (csv_a, csv_b) = (read(&a), read(&b));
    assert!(csv_a.len() > 10_000, "{}", csv_a.len());
    assert!(csv_a == csv_b, "two runs of the same options differ");
}

/// With `[coil] model` (SimNIBS's Magstim D70): each controller is scored in dose as well, the
/// field at the target against the goal's, in the JSON, the CSV, the summary and a figure; the
/// paper's lagging pipeline misses the dose by more than mocomp, and mocomp by no less than the
/// oracle's bound.
#[test]
fn with_a_coil_model_the_demo_scores_each_controller_in_dose() {
    let dir = TempDir::new("mocomp-demo-dose");
    let out_dir = dir.path("out");
    let model = mocomp_testkit::workspace_root()
        .join("crates/mocomp-efield/tests/data/coils/MagStim_D70.ccd");
    let config = dir.path("dose.toml");
    std::fs::write(
        &config,
        format!(
            "[coil]\nmodel = {:?}\noutput_pct = 80.0\n",
            model.display().to_string()
        ),
    )
    .unwrap();
    let out = demo_json(
        &out_dir,
        "4",
        ("127.0.0.150", "127.0.0.151"),
        &[
            "--config",
            &config,
            "--motion",
            "nods",
            "--controllers",
            "paper,mocomp,oracle",
        ],
    );
    assert_success(&out);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = j["controllers"].as_array().unwrap();
    let dose = |r: &serde_json::Value, k: &str| r[format!("dose_error_pct_{k}")].as_f64().unwrap();
    for r in rows {
        let (rms, p95, max) = (dose(r, "rms"), dose(r, "p95"), dose(r, "max"));
        assert!(rms >= 0.0 && p95 >= 0.0 && rms <= max && p95 <= max, "{r}");
    }
    let (paper, mocomp, oracle) = (&rows[0], &rows[1], &rows[2]);
    for r in rows {
        eprintln!(
            "{}: dose error RMS {:.3} %, p95 {:.3} %, max {:.3} %; translation p95 {:.3} mm",
            r["controller"],
            dose(r, "rms"),
            dose(r, "p95"),
            dose(r, "max"),
            r["translation_mm_p95"]
        );
    }
    assert!(dose(paper, "p95") > 2.0 * dose(mocomp, "p95"), "{j}");
    assert!(dose(oracle, "rms") <= dose(mocomp, "rms") + 0.05, "{j}");
    // The CSV's column is the same dose, tick by tick.
    let csv = std::fs::read_to_string(format!("{out_dir}/demo.csv")).unwrap();
    assert!(
        csv.lines()
            .next()
            .unwrap()
            .ends_with(",standoff_mm,dose_pct")
    );
    let worst = csv
        .lines()
        .filter(|l| l.starts_with("mocomp,"))
        .map(|l| (l.rsplit(',').next().unwrap().parse::<f64>().unwrap() - 100.0).abs())
        .fold(0.0, f64::max);
    assert!((worst - dose(mocomp, "max")).abs() < 1e-3, "{worst} {j}");
    let summary = std::fs::read_to_string(format!("{out_dir}/summary.md")).unwrap();
    assert!(
        summary.contains("The dose: the field the coil (D70, 964 dipoles, 91.8 A/µs)"),
        "{summary}"
    );
    assert!(std::path::Path::new(&format!("{out_dir}/dose.png")).exists());
}

/// `--pulses-hz`: a stimulator pulsing through the gate during mocomp's run, the gate holding
/// pulses to `[session.gate] max_dose_error_pct`; the summary scores each pulse by the truth (the
/// true coil against the goal on the true head, and the dose it gave the target), which the
/// gate, judging the measured coil, does not see.
#[test]
fn a_pulsing_session_scores_every_pulse_through_the_gate_by_the_truth_and_in_dose() {
    let dir = TempDir::new("mocomp-demo-pulses");
    let out_dir = dir.path("out");
    let model = mocomp_testkit::workspace_root()
        .join("crates/mocomp-efield/tests/data/coils/MagStim_D70.ccd");
    let config = dir.path("pulses.toml");
    std::fs::write(
        &config,
        format!(
            "[coil]\nmodel = {:?}\n[session.gate]\nmax_dose_error_pct = 1.0\n",
            model.display().to_string()
        ),
    )
    .unwrap();
    let out = demo_json(
        &out_dir,
        "6",
        ("127.0.0.164", "127.0.0.165"),
        &["--config", &config, "--motion", "nods", "--pulses-hz", "5"],
    );
    assert_success(&out);
    // The gate's key is the experiment's now: no note calls it unused.
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("session.gate"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = j["controllers"].as_array().unwrap();
    assert!(
        rows[0].get("pulses").is_none(),
        "the paper's run has no session: {j}"
    );
    let p = &rows[1]["pulses"];
    eprintln!("mocomp's pulses: {p}");
    let through = p["through_gate"].as_u64().unwrap();
    let withheld = p["withheld"].as_u64().unwrap();
    // 29 tries at 5 Hz over 6 s; those while the coil still approaches, and those where the
    // nodding head took the measured dose more than 1 % off, are withheld.
    assert_eq!(through + withheld, 29, "{p}");
    assert!(through >= 15 && withheld >= 1, "{p}");
    // The gate judged the measured dose within 1 %; the truth (2026-12-06: 1.35 % at worst)
    // differs from it by what the tracker's noise and latency hide.
    let dose = p["dose_error_pct_max"].as_f64().unwrap();
    assert!(dose > 0.0 && dose < 2.0, "{p}");
    assert!(p["error_mm_max"].as_f64().unwrap() < 1.0, "{p}");
    let summary = std::fs::read_to_string(format!("{out_dir}/summary.md")).unwrap();
    assert!(
        summary.contains(&format!(
            "Pulses (mocomp): {through} through the gate, {withheld} withheld"
        )),
        "{summary}"
    );
}
