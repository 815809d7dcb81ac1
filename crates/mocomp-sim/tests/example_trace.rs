#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! `examples/head-irregular-60s.csv`, the irregular head trace the README's figures are measured
//! on, is what its seeded generator writes (so it cannot drift from the script that documents
//! it), and it has the properties it is there for: samples 10–90 ms apart while the head moves,
//! still spells of seconds, onsets from rest within a sample or two.

use mocomp_sim::trace::MotionTrace;
use std::path::Path;
use std::process::Command;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .parent()
        .unwrap()
}

#[test]
fn the_example_trace_is_its_generators_output_and_irregular_as_stated() {
    let committed = root().join("examples/head-irregular-60s.csv");
    let out = std::env::temp_dir().join(format!("mocomp-trace-{}.csv", std::process::id()));
    let status = Command::new("python3")
        .arg(root().join("scripts/irregular_head_trace.py"))
        .arg(&out)
        .args(["--seed", "33", "--seconds", "60"])
        .status()
        .expect("python3 runs the generator");
    assert!(status.success());
    let (want, got) = (
        std::fs::read_to_string(&committed).unwrap(),
        std::fs::read_to_string(&out).unwrap(),
    );
    std::fs::remove_file(&out).ok();
    // The generator names its output file in the header; the rest is byte for byte.
    let body = |t: &str| t.lines().skip(3).collect::<Vec<_>>().join("\n");
    assert_eq!(
        body(&want),
        body(&got),
        "examples/head-irregular-60s.csv is stale"
    );

    let trace = MotionTrace::load(&committed).unwrap();
    assert!(trace.duration_s() >= 59.0, "{}", trace.duration_s());
    let t: Vec<f64> = want
        .lines()
        .filter(|l| !l.starts_with('#') && !l.starts_with("t_s"))
        .map(|l| l.split(',').next().unwrap().parse().unwrap())
        .collect();
    let gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let longest = gaps.iter().cloned().fold(0.0, f64::max);
    let moving = gaps.iter().filter(|g| **g <= 0.09 + 1e-9).count();
    assert!(
        (4.0..=5.6 + 1e-9).contains(&longest),
        "longest still gap {longest}"
    );
    assert!(gaps.iter().all(|g| *g > 0.0), "times increase");
    assert!(
        moving * 10 > gaps.len() * 8,
        "{moving} of {} gaps while moving",
        gaps.len()
    );
    // Onsets: somewhere the head goes from still to 30 mm/s or more within one sample.
    let fastest_onset = (1..gaps.len())
        .filter(|&i| gaps[i - 1] > 0.9)
        .map(|i| {
            let (a, b) = (trace.rest_from_head(t[i]), trace.rest_from_head(t[i + 1]));
            (b.translation.vector - a.translation.vector).norm() / gaps[i]
        })
        .fold(0.0, f64::max);
    assert!(fastest_onset > 0.03, "fastest onset {fastest_onset} m/s");
}
