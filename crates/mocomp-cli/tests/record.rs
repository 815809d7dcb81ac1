#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! `mocomp run --record FILE.mcap`: the live session recorded as MCAP with the ROS 2 profile,
//! read back by the PyPI `mcap` reader with `mcap-ros2-support` (which decodes each message
//! with the `.msg` schema the file carries): every message decoded, the counts and values those
//! of the run.

mod common;
use common::{assert_success, example_changed, mocomp, run_args};
use mocomp_testkit::{PythonPeer, TempDir};
use serde_json::json;

/// The command's JSON summary (its recording without an error) and the recording as the ROS 2
/// MCAP reader decodes it (every message decoded, the count the summary says written).
fn read_back(out: &std::process::Output, mcap: &str) -> (serde_json::Value, serde_json::Value) {
    assert_success(out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["record"]["error"].is_null(), "{v}");
    let mut py = PythonPeer::start("mcap_peer.py", "mcap-ros2-support", "0.6.0");
    let r = py.request(&json!({"op": "read", "path": mcap}));
    eprintln!("recorded: {}", r["counts"]);
    assert_eq!(r["profile"], "ros2");
    assert_eq!(r["undecoded"], 0, "{}", r["counts"]);
    let total: u64 = r["counts"]
        .as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert_eq!(v["record"]["messages"].as_u64().unwrap(), total);
    (v, r)
}

/// The rows of a CSV file.
fn csv_rows(path: &str) -> Vec<csv::StringRecord> {
    let mut reader = csv::Reader::from_path(path).unwrap();
    reader.records().map(Result::unwrap).collect()
}

/// The `/mocomp/cycle` records' loop times.
fn cycle_times(r: &serde_json::Value) -> Vec<f64> {
    r["cycle_t"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_f64().unwrap())
        .collect()
}

#[test]
fn a_recorded_run_reads_back_in_the_ros_2_mcap_reader_message_for_message() {
    let dir = TempDir::new("mocomp-record");
    let path = example_changed(&dir, "127.0.0.83", &[]);
    let mcap = dir.path("run.mcap");
    let csv = dir.path("run.csv");
    let out = mocomp(&run_args(
        &path,
        "4",
        &["--record", &mcap, "--log-csv", &csv],
    ));
    let (v, r) = read_back(&out, &mcap);
    let cycles = v["cycles"].as_u64().unwrap();
    // Every cycle's record, and every cycle's ROS 2 messages (the arm's state was measured from
    // the first cycle on).
    let count = |t: &str| r["counts"][t].as_u64().unwrap_or(0);
    assert_eq!(count("/mocomp/cycle"), cycles);
    for t in ["/joint_states", "/tf", "/mocomp/coil_pose"] {
        assert_eq!(count(t), cycles, "{t}");
    }
    assert!(count("/mocomp/head_pose") > cycles / 2);
    assert!((3..=5).contains(&count("/diagnostics")), "{}", r["counts"]);
    assert_eq!(r["schemas"]["/joint_states"], "sensor_msgs/msg/JointState");
    assert_eq!(r["schemas"]["/mocomp/cycle"], "mocomp_msgs/msg/CycleRecord");
    // The cycle records are the CSV's, row for row.
    let rows = csv_rows(&csv);
    let cycle_t = cycle_times(&r);
    assert_eq!(cycle_t.len(), rows.len());
    for (t, row) in cycle_t.iter().zip(&rows) {
        let csv_t: f64 = row[0].parse().unwrap();
        assert!((t - csv_t).abs() < 1e-6, "{t} vs {csv_t}");
    }
    let last = &r["last"]["/mocomp/cycle"];
    let q_csv: Vec<f64> = (18..24)
        .map(|i| rows.last().unwrap()[i].parse().unwrap())
        .collect();
    for (a, b) in last["q_actual"].as_array().unwrap().iter().zip(&q_csv) {
        assert!((a.as_f64().unwrap() - b).abs() < 1e-5, "{last}");
    }
    // The fields after the joints decode too (the schema is the encoding's): no coil model,
    // no dose (NaN, which the reader's JSON gives as null).
    for key in ["dose_pct", "dose_v_per_m"] {
        assert!(last.get(key).is_some_and(|v| v.is_null()), "{key}: {last}");
    }
    assert!(last["compute_ns"].as_u64().unwrap() > 0, "{last}");
    let js = &r["last"]["/joint_states"];
    assert_eq!(js["name"][0], "shoulder_pan_joint");
    let tf = &r["last"]["/tf"]["transforms"];
    assert_eq!(tf[0]["child_frame_id"], "tool0");
    assert!(r["last"]["/diagnostics"]["status"][0]["message"].is_string());
}

#[test]
fn a_recorded_demo_holds_both_runs_in_order_each_cycle_naming_its_controller() {
    let dir = TempDir::new("mocomp-record-demo");
    let mcap = dir.path("demo.mcap");
    let out_dir = dir.path("out");
    let seconds = 4.0;
    let out = mocomp(&[
        "demo",
        "--seconds",
        &seconds.to_string(),
        "--record",
        &mcap,
        "--out",
        &out_dir,
        "--coil-host",
        "127.0.0.84",
        "--head-host",
        "127.0.0.85",
        "--quiet",
        "--json",
    ]);
    let (_, r) = read_back(&out, &mcap);
    assert_eq!(r["in_time_order"], true);
    // Every tick of both runs, as the demo's CSV has them: the paper's run, then mocomp's.
    let rows = csv_rows(&format!("{out_dir}/demo.csv"));
    let controllers: Vec<&str> = r["cycle_controller"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    let csv_controllers: Vec<&str> = rows.iter().map(|row| &row[0]).collect();
    assert_eq!(controllers, csv_controllers);
    assert_eq!(controllers.first(), Some(&"paper"));
    assert_eq!(controllers.last(), Some(&"mocomp"));
    // Each record's clock is the CSV's time in its run, shifted by the run's start.
    let cycle_t = cycle_times(&r);
    for name in ["paper", "mocomp"] {
        let ts: Vec<(f64, f64)> = cycle_t
            .iter()
            .zip(&rows)
            .filter(|(_, row)| &row[0] == name)
            .map(|(t, row)| (*t, row[1].parse::<f64>().unwrap()))
            .collect();
        let shift = ts[0].0 - ts[0].1;
        for (t, csv_t) in &ts {
            assert!((t - csv_t - shift).abs() < 1e-6, "{name}: {t} vs {csv_t}");
        }
    }
    // Both runs' arms and heads, from the first cycle (the robot is measured before it).
    let count = |t: &str| r["counts"][t].as_u64().unwrap_or(0);
    let cycles = rows.len() as u64;
    for t in ["/mocomp/cycle", "/joint_states", "/tf", "/mocomp/coil_pose"] {
        assert_eq!(count(t), cycles, "{t}");
    }
    assert!(count("/mocomp/head_pose") > cycles * 9 / 10);
    // The status once a second of each run, naming its controller.
    let per_run = seconds as u64;
    assert!(
        (2 * (per_run - 1)..=2 * per_run).contains(&count("/diagnostics")),
        "{}",
        r["counts"]
    );
    let named = |which: &str| {
        let values = r[which]["/diagnostics"]["status"][0]["values"].clone();
        values
            .as_array()
            .unwrap()
            .iter()
            .find(|kv| kv["key"] == "controller")
            .map(|kv| kv["value"].clone())
            .unwrap()
    };
    assert_eq!(named("first"), "paper");
    assert_eq!(named("last"), "mocomp");
    // The last joint state is the last cycle's measured arm.
    let q_js = r["last"]["/joint_states"]["position"].as_array().unwrap();
    let q_rec = r["last"]["/mocomp/cycle"]["q_actual"].as_array().unwrap();
    assert_eq!(q_js, q_rec);
}
