//! Calibration solve times. `cargo bench -p mocomp-calib --bench calib`.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_calib::synth::{SynthOptions, synthesize};
use mocomp_calib::{Method, SolveOptions, solve};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    for count in [20usize, 200] {
        let pairs = synthesize(&SynthOptions {
            count,
            seed: 7,
            ..SynthOptions::default()
        })
        .unwrap();
        for method in [Method::Li, Method::Shah, Method::Refined] {
            let opts = SolveOptions {
                method,
                ..SolveOptions::default()
            };
            c.bench_function(&format!("solve_{}_n{count}", method.name()), |b| {
                b.iter(|| black_box(solve(black_box(&pairs), &opts).unwrap()))
            });
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
