//! One 512×424 frame through the whole pipeline. `cargo bench -p mocomp-vision --bench vision`.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_vision::render::{Distractors, RenderOptions, render, view_pose};
use mocomp_vision::{Frame, Intrinsics, MarkerGeometry, TrackParams, Tracker};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let g = MarkerGeometry::ndi_8700449();
    let mut o = RenderOptions::kinect(view_pose(3), 3);
    let clean = render(&g, &o);
    o.distractors = Distractors {
        sun_spots: 2,
        reflections: 6,
        hand: true,
        placement_seed: None,
    };
    let busy = render(&g, &o);
    let mut tracker = Tracker::new(Intrinsics::kinect_v2(), TrackParams::default(), g).unwrap();
    for (name, img) in [
        ("frame_512x424_clean", &clean),
        ("frame_512x424_distractors", &busy),
    ] {
        let frame = Frame::new(img.width, img.height, &img.ir, &img.depth).unwrap();
        assert!(tracker.process(&frame).unwrap().detection.is_some());
        c.bench_function(name, |b| {
            b.iter(|| black_box(tracker.process(black_box(&frame)).unwrap()))
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
