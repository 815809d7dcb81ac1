//! The compensation cycle's compute time: tracker rules, prediction, goal, IK on the current
//! branch, limits, collision check of the command. The robot here is in memory (it follows the
//! command exactly and reports a healthy state), so the figure is the cycle's own work, without
//! the socket write of the real client; `mocomp run` reports the live figure with it.
//!
//! Besides criterion's median, the bench times 20,000 consecutive cycles one by one on a nodding,
//! noisy head and prints their median, p99 and max (the goal: p99 under 20 µs), for each
//! head model in the same run: the ellipsoid, FreeSurfer's fsaverage scalp (4 k triangles, from
//! MNE through the interop peer, which `scripts/test.sh` installs) and that scalp split to
//! 110 k triangles (a clinical scalp's size); and on the ellipsoid without the learned
//! prediction (`[predictor] learned = false`), for its cost.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // bench code

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_control::{HeadModel, Mode};
use mocomp_geom::nalgebra::Point3;
use mocomp_head::{Head, Mesh, MeshHead, repair};
use std::sync::Arc;
use std::time::Instant;

#[path = "../tests/common/mem.rs"]
mod mem;
use mem::World;

/// The heads: the ellipsoid, the fsaverage scalp, and that scalp split to 110 k triangles.
fn heads() -> Vec<(String, HeadModel)> {
    let (v, t) = mocomp_testkit::anatomy::fsaverage_head();
    let raw = Mesh {
        vertices: v.iter().map(|p| Point3::from(*p)).collect(),
        triangles: t,
    };
    let (mesh, _) = repair(raw, "fsaverage").unwrap();
    let fine = mesh
        .split_at_centroids()
        .split_at_centroids()
        .split_at_centroids();
    let mut out = vec![("ellipsoid".to_string(), HeadModel::adult())];
    for m in [mesh, fine] {
        let name = format!("fsaverage {} k", m.triangles.len() / 1000);
        let t0 = Instant::now();
        let head = MeshHead::new(m, &name).unwrap();
        eprintln!(
            "{name}: built in {:.2} s, about {:.1} MB",
            t0.elapsed().as_secs_f64(),
            head.memory_bytes() as f64 / 1e6
        );
        out.push((name, HeadModel::new(Head::Mesh(Arc::new(head)))));
    }
    out
}

fn percentiles(name: &str, head: &HeadModel, learned: bool) {
    let mut w = World::with_config(head.clone(), |c| c.predictor.learned = learned);
    let mut ns: Vec<u64> = Vec::with_capacity(20_000);
    let mut tracking = 0;
    for _ in 0..20_000 {
        let t0 = Instant::now();
        let mode = std::hint::black_box(w.cycle());
        ns.push(t0.elapsed().as_nanos() as u64);
        tracking += usize::from(mode == Mode::Tracking);
    }
    ns.sort_unstable();
    let at = |p: f64| ns[((ns.len() - 1) as f64 * p) as usize] as f64 / 1e3;
    eprintln!(
        "cycle on the {name}, 20,000 consecutive (tracking {tracking}): median {:.2} µs, p99 {:.2} µs, max {:.2} µs",
        at(0.5),
        at(0.99),
        at(1.0)
    );
}

fn bench(c: &mut Criterion) {
    let heads = heads();
    for (name, head) in &heads {
        percentiles(name, head, true);
    }
    // What the learned prediction costs, in the same run.
    percentiles(
        "ellipsoid, the filter alone (learned = false)",
        &heads[0].1,
        false,
    );
    for (name, head) in &heads {
        let mut w = World::with_head(head.clone());
        c.bench_function(&format!("cycle (tracking a nodding head), {name}"), |b| {
            b.iter(|| std::hint::black_box(w.cycle()))
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
