//! Times the pipeline on a directory of frames, for `bench/vision_vs_opencv.py`.
//!
//! `cargo run --release -p mocomp-vision --example vision_bench -- DIR GEOMETRY.toml ROUNDS`
//! Frames (`<name>_ir.png`, `<name>_depth.png`) and `intrinsics.toml` are loaded first; only
//! `Tracker::process` is timed. Prints one JSON object: per-frame median microseconds and poses.
#![allow(clippy::print_stdout, missing_docs)]

use mocomp_geom::rows_from_iso;
use mocomp_vision::codec::decode_gray16_png;
use mocomp_vision::{Frame, Intrinsics, MarkerGeometry, TrackParams, Tracker};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let [_, dir, geometry, rounds] = args.as_slice() else {
        return Err("usage: vision_bench DIR GEOMETRY ROUNDS".into());
    };
    let rounds: usize = rounds.parse()?;
    let dir = std::path::Path::new(dir);
    let intr = Intrinsics::from_toml_str(
        &std::fs::read_to_string(dir.join("intrinsics.toml"))?,
        "intrinsics.toml",
    )?;
    let g = MarkerGeometry::from_file_bytes(&std::fs::read(geometry)?, geometry)?;
    let mut names: Vec<String> = std::fs::read_dir(dir)?
        .filter_map(|e| {
            e.ok()?
                .file_name()
                .to_str()?
                .strip_suffix("_ir.png")
                .map(String::from)
        })
        .collect();
    names.sort();
    let mut frames = Vec::new();
    for n in &names {
        let ir = decode_gray16_png(&std::fs::read(dir.join(format!("{n}_ir.png")))?, n)?;
        let depth = decode_gray16_png(&std::fs::read(dir.join(format!("{n}_depth.png")))?, n)?;
        frames.push((ir, depth));
    }
    let mut tracker = Tracker::new(intr, TrackParams::default(), g)?;
    let mut results = Vec::new();
    for (n, (ir, depth)) in names.iter().zip(&frames) {
        let frame = Frame::new(ir.width, ir.height, &ir.data, &depth.data)?;
        let mut times = Vec::with_capacity(rounds);
        let mut last = None;
        for _ in 0..rounds {
            let t0 = Instant::now();
            let r = tracker.process(&frame)?;
            times.push(t0.elapsed().as_secs_f64() * 1e6);
            last = Some(r);
        }
        times.sort_by(f64::total_cmp);
        let pose = last
            .and_then(|r| r.detection)
            .map(|d| rows_from_iso(&d.tracker_from_marker));
        results.push(serde_json::json!({"frame": n, "us": times[times.len() / 2], "pose": pose}));
    }
    println!("{}", serde_json::json!({ "frames": results }));
    Ok(())
}
