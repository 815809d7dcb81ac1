//! Times our IK and FK on poses from a file, for `bench/ik_vs_ur_analytic_ik.py`.
//!
//! `cargo run --release -p mocomp-kin --example ik_throughput -- MODEL POSES.json ROUNDS`
//! where POSES.json is `{"joints": [[6]...], "poses": [[4x4 rows]...]}`. Prints one JSON object:
//! median nanoseconds per all-solution IK and per FK over the rounds.
#![allow(clippy::print_stdout, missing_docs)]

use mocomp_geom::{RIGID_TOLERANCE, iso_from_rows};
use mocomp_kin::{Arm, Model};
use std::hint::black_box;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, model, path, rounds] = args.as_slice() else {
        return Err("usage: ik_throughput MODEL POSES.json ROUNDS".into());
    };
    let model: Model = model.parse()?;
    let rounds: usize = rounds.parse()?;
    let data: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path)?)?;
    let poses = data["poses"]
        .as_array()
        .ok_or("poses")?
        .iter()
        .map(|p| {
            let rows: [[f64; 4]; 4] = serde_json::from_value(p.clone())?;
            Ok(iso_from_rows(&rows, RIGID_TOLERANCE)?)
        })
        .collect::<Result<Vec<_>, Box<dyn std::error::Error>>>()?;
    let joints: Vec<[f64; 6]> = serde_json::from_value(data["joints"].clone())?;
    let arm = Arm::new(model);

    let mut ik_ns = Vec::with_capacity(rounds);
    let mut fk_ns = Vec::with_capacity(rounds);
    let mut solutions = 0usize;
    for _ in 0..rounds {
        let t0 = Instant::now();
        let mut n = 0usize;
        for p in &poses {
            if let Ok(s) = arm.ik(black_box(p), 0.0) {
                n += s.len();
            }
        }
        ik_ns.push(t0.elapsed().as_nanos() as f64 / poses.len() as f64);
        solutions = n;
        let t0 = Instant::now();
        for q in &joints {
            black_box(arm.fk(black_box(q)));
        }
        fk_ns.push(t0.elapsed().as_nanos() as f64 / joints.len() as f64);
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "{}",
        serde_json::json!({
            "model": model.name(),
            "poses": poses.len(),
            "rounds": rounds,
            "ik_ns_median": median(&mut ik_ns),
            "fk_ns_median": median(&mut fk_ns),
            "solutions_per_round": solutions,
        })
    );
    Ok(())
}
