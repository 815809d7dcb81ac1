//! One frame through the whole pipeline: a Kinect v2's 512×424, and an Azure Kinect's 640×576
//! (NFOV unbinned, its factory lens: the rational model). `cargo bench -p mocomp-vision --bench
//! vision`.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_vision::intrinsics::PixelCentre;
use mocomp_vision::render::{Distractors, RenderOptions, render, view_pose};
use mocomp_vision::{Frame, Intrinsics, MarkerGeometry, TrackParams, Tracker};
use std::hint::black_box;

/// The Azure Kinect DK of `mocomp-k4a`'s test recording, NFOV unbinned, as its SDK reports it.
fn azure_kinect() -> Intrinsics {
    Intrinsics {
        width: 640,
        height: 576,
        fx: 504.607_635_5,
        fy: 504.732_513_4,
        cx: 332.781_066_9,
        cy: 348.829_711_9,
        k1: 0.547_939_777,
        k2: -0.020_971_371,
        k3: -0.002_652_232,
        k4: 0.889_679_074,
        k5: 0.086_130_209,
        k6: -0.013_910_385,
        p1: 2.055_753e-5,
        p2: -7.210_416e-5,
        pixel_centre: PixelCentre::Integer,
    }
}

fn bench(c: &mut Criterion) {
    let g = MarkerGeometry::ndi_8700449();
    for (size, intrinsics) in [
        ("512x424", Intrinsics::kinect_v2()),
        ("640x576", azure_kinect()),
    ] {
        let mut tracker = Tracker::new(intrinsics, TrackParams::default(), g.clone()).unwrap();
        // The first seeded view (from 3) in which the marker is found despite the distractors
        // (a hand may cover it), and the same view clean.
        let (clean, busy) = (3..)
            .map(|seed| {
                let mut o = RenderOptions::kinect(view_pose(seed), seed);
                o.intrinsics = intrinsics;
                let clean = render(&g, &o);
                o.distractors = Distractors {
                    sun_spots: 2,
                    reflections: 6,
                    hand: true,
                    placement_seed: None,
                };
                (clean, render(&g, &o))
            })
            .find(|(_, busy)| {
                let frame = Frame::new(busy.width, busy.height, &busy.ir, &busy.depth).unwrap();
                tracker.process(&frame).unwrap().detection.is_some()
            })
            .unwrap();
        for (what, img) in [("clean", &clean), ("distractors", &busy)] {
            let frame = Frame::new(img.width, img.height, &img.ir, &img.depth).unwrap();
            assert!(tracker.process(&frame).unwrap().detection.is_some());
            c.bench_function(&format!("frame_{size}_{what}"), |b| {
                b.iter(|| black_box(tracker.process(black_box(&frame)).unwrap()))
            });
        }
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
