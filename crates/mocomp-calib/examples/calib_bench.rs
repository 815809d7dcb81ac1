//! Solves seeded synthetic calibration sets with our three methods and times them, for
//! `bench/handeye_vs_opencv.py`, which runs OpenCV on the same sets.
//!
//! `cargo run --release -p mocomp-calib --example calib_bench -- COUNTS TRIALS REPEAT SEED`
//! (COUNTS comma-separated; set t of size N uses seed SEED + 10000·N + t). Prints one JSON object with every set, the truth, and our results.
#![allow(clippy::print_stdout, missing_docs)]

use mocomp_calib::synth::{SynthOptions, synthesize};
use mocomp_calib::{Method, SolveOptions, solve};
use mocomp_geom::rows_from_iso;
use serde_json::json;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, counts, trials, repeat, seed] = args.as_slice() else {
        return Err("usage: calib_bench COUNTS TRIALS REPEAT SEED".into());
    };
    let seed: u64 = seed.parse()?;
    let counts: Vec<usize> = counts
        .split(',')
        .map(str::parse)
        .collect::<Result<_, _>>()?;
    let trials: u64 = trials.parse()?;
    let repeat: usize = repeat.parse()?;
    let mut cases = Vec::new();
    for &count in &counts {
        for t in 0..trials {
            let o = SynthOptions {
                count,
                seed: seed + 10_000 * count as u64 + t,
                ..SynthOptions::default()
            };
            let pairs = synthesize(&o)?;
            let mut ours = serde_json::Map::new();
            for method in [Method::Li, Method::Shah, Method::Refined] {
                let opts = SolveOptions {
                    method,
                    ..SolveOptions::default()
                };
                let mut times = Vec::with_capacity(repeat);
                let mut c = None;
                for _ in 0..repeat {
                    let t0 = Instant::now();
                    c = Some(solve(&pairs, &opts)?);
                    times.push(t0.elapsed().as_secs_f64());
                }
                times.sort_by(f64::total_cmp);
                let c = c.ok_or("no repeat")?;
                ours.insert(
                    method.name().to_string(),
                    json!({
                        "X": rows_from_iso(&c.flange_from_marker),
                        "Y": rows_from_iso(&c.base_from_tracker),
                        "seconds": times[times.len() / 2],
                    }),
                );
            }
            cases.push(json!({
                "count": count,
                "seed": o.seed,
                "truth": {"X": rows_from_iso(&o.flange_from_marker), "Y": rows_from_iso(&o.base_from_tracker)},
                "pairs": {
                    "base_from_flange": pairs.iter().map(|p| rows_from_iso(&p.base_from_flange)).collect::<Vec<_>>(),
                    "tracker_from_marker": pairs.iter().map(|p| rows_from_iso(&p.tracker_from_marker)).collect::<Vec<_>>(),
                },
                "ours": ours,
            }));
        }
    }
    println!("{}", json!({ "cases": cases }));
    Ok(())
}
