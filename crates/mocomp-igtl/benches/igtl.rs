//! Decoding throughput with CRC. `cargo bench -p mocomp-igtl --bench igtl`.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_igtl::codec::DEFAULT_MAX_BODY;
use mocomp_igtl::{Decoder, Message, MetaEntry, Timestamp, encode};
use std::hint::black_box;

fn stream(n: usize, v2: bool) -> Vec<u8> {
    let mut out = Vec::new();
    for k in 0..n {
        let pose = Isometry3::new(
            Vector3::new(0.1, 0.2, k as f64 * 1e-4),
            Vector3::new(0.1, 0.2, 0.3),
        );
        let mut m = Message::transform(
            "HeadToTracker",
            &pose,
            Timestamp::from_secs_f64(1.7e9 + k as f64 * 1e-3),
        )
        .unwrap();
        if v2 {
            m = m.with_metadata(vec![MetaEntry::text("TransformStatus", "OK")]);
        }
        out.extend(encode(&m));
    }
    out
}

fn bench(c: &mut Criterion) {
    let n = 10_000;
    for (name, v2) in [
        ("decode_transform_v1", false),
        ("decode_transform_v2_status", true),
    ] {
        let bytes = stream(n, v2);
        let mut g = c.benchmark_group(name);
        g.throughput(Throughput::Elements(n as u64));
        g.bench_function("10k", |b| {
            b.iter(|| {
                let mut d = Decoder::new(DEFAULT_MAX_BODY);
                d.feed(black_box(&bytes));
                let mut count = 0;
                while let Some(r) = d.next_message() {
                    black_box(r.unwrap());
                    count += 1;
                }
                assert_eq!(count, n);
            })
        });
        g.finish();
    }
    let m = Message::transform("HeadToTracker", &Isometry3::identity(), Timestamp::now()).unwrap();
    c.bench_function("encode_transform_v1", |b| {
        b.iter(|| black_box(encode(black_box(&m))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
