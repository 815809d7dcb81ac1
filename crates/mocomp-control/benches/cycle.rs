//! The compensation cycle's compute time: tracker rules, prediction, goal, IK on the current
//! branch, limits, collision check of the command. The robot here is in memory (it follows the
//! command exactly and reports a healthy state), so the figure is the cycle's own work, without
//! the socket write of the real client; `mocomp run` reports the live figure with it.
//!
//! Besides criterion's median, the bench times 20,000 consecutive cycles one by one on a nodding,
//! noisy head and prints their median, p99 and max (the goal: p99 under 20 µs).
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // bench code

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_control::Mode;
use std::time::Instant;

#[path = "../tests/common/mem.rs"]
mod mem;
use mem::World;

fn percentiles() {
    let mut w = World::new();
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
        "cycle, 20,000 consecutive (tracking {tracking}): median {:.2} µs, p99 {:.2} µs, max {:.2} µs",
        at(0.5),
        at(0.99),
        at(1.0)
    );
}

fn bench(c: &mut Criterion) {
    percentiles();
    let mut w = World::new();
    c.bench_function("cycle (tracking a nodding head)", |b| {
        b.iter(|| std::hint::black_box(w.cycle()))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
