//! FK and IK throughput. `cargo bench -p mocomp-kin --bench kin`.
#![allow(missing_docs)]

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_kin::{Arm, Model, Selection};
use std::hint::black_box;

/// Deterministic joint samples (a fixed LCG; the bench must not depend on a RNG crate's version).
fn samples(n: usize) -> Vec<[f64; 6]> {
    let mut state: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 * std::f64::consts::PI
            - std::f64::consts::PI
    };
    (0..n).map(|_| std::array::from_fn(|_| next())).collect()
}

fn bench(c: &mut Criterion) {
    let arm = Arm::new(Model::Ur5e);
    let qs = samples(1024);
    let poses: Vec<_> = qs.iter().map(|q| arm.fk(q)).collect();

    let mut i = 0;
    c.bench_function("fk_flange_ur5e", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(arm.fk_flange(black_box(&qs[i])))
        })
    });
    let mut i = 0;
    c.bench_function("link_frames_ur5e", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(arm.link_frames(black_box(&qs[i])))
        })
    });
    let mut i = 0;
    c.bench_function("ik_all_solutions_ur5e", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(arm.ik(black_box(&poses[i]), 0.0))
        })
    });
    let mut i = 0;
    let sel = Selection::tracking(0.0);
    c.bench_function("ik_closest_ur5e", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(arm.ik_closest(black_box(&poses[i]), &qs[i], &sel))
        })
    });
    let mut i = 0;
    c.bench_function("jacobian_ur5e", |b| {
        b.iter(|| {
            i = (i + 1) & 1023;
            black_box(arm.jacobian(black_box(&qs[i])))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
