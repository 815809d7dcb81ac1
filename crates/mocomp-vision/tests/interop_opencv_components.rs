//! Interop: our labelling and blob statistics against OpenCV's `connectedComponentsWithStats`
//! (8-connected) on the same binary images: rendered frames with distractors, random masks dense
//! enough to make large, tangled components, and patterns that separate 4- from 8-connectivity.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_testkit::{PythonPeer, SplitMix64};
use mocomp_vision::blobs::{Blob, Gates, Labeler};
use mocomp_vision::params::CentroidWeighting;
use mocomp_vision::render::{Distractors, RenderOptions, render, view_pose};
use mocomp_vision::{Frame, MarkerGeometry};
use serde_json::json;

fn ours(w: u32, h: u32, mask: &[bool]) -> Vec<Blob> {
    let ir: Vec<u16> = mask.iter().map(|&m| if m { 1000 } else { 0 }).collect();
    let depth = vec![0u16; ir.len()];
    let frame = Frame::new(w, h, &ir, &depth).unwrap();
    let gates = Gates {
        threshold: 500,
        depth_range: (1, 60_000),
        area: [0, 0, w, h],
        weighting: CentroidWeighting::Binary,
    };
    let mut out = Vec::new();
    Labeler::new().label(&frame, &gates, &mut out);
    out
}

fn compare(peer: &mut PythonPeer, name: &str, w: u32, h: u32, mask: &[bool]) -> usize {
    let text: String = mask.iter().map(|&m| if m { '1' } else { '0' }).collect();
    let v = peer.request(&json!({"op": "components", "width": w, "height": h, "mask": text}));
    let mut cv: Vec<([i64; 5], [f64; 2])> = v["stats"]
        .as_array()
        .unwrap()
        .iter()
        .zip(v["centroids"].as_array().unwrap())
        .map(|(s, c)| {
            (
                std::array::from_fn(|k| s[k].as_i64().unwrap()),
                [c[0].as_f64().unwrap(), c[1].as_f64().unwrap()],
            )
        })
        .collect();
    let mut mine: Vec<([i64; 5], [f64; 2])> = ours(w, h, mask)
        .iter()
        .map(|b| {
            let [x0, y0, x1, y1] = b.bbox.map(i64::from);
            (
                [x0, y0, x1 - x0 + 1, y1 - y0 + 1, i64::from(b.area)],
                [b.centroid_unweighted.0, b.centroid_unweighted.1],
            )
        })
        .collect();
    assert_eq!(
        mine.len(),
        v["count"].as_u64().unwrap() as usize,
        "{name}: component count"
    );
    let key = |e: &([i64; 5], [f64; 2])| (e.0[1], e.0[0], e.0[4]);
    cv.sort_by_key(key);
    mine.sort_by_key(key);
    for (a, b) in mine.iter().zip(&cv) {
        assert_eq!(a.0, b.0, "{name}: stats [left, top, width, height, area]");
        assert!(
            (a.1[0] - b.1[0]).abs() < 1e-9 && (a.1[1] - b.1[1]).abs() < 1e-9,
            "{name}: centroid {:?} vs {:?}",
            a.1,
            b.1
        );
    }
    mine.len()
}

#[test]
fn labelling_matches_opencv() {
    let mut peer = PythonPeer::start("opencv_vision_peer.py", "opencv-python-headless", "4.14.0");
    let g = MarkerGeometry::ndi_8700449();
    let mut total = 0;
    // Rendered frames with distractors, thresholded.
    for seed in 0..4 {
        let mut o = RenderOptions::kinect(view_pose(seed), seed);
        o.distractors = Distractors {
            sun_spots: 2,
            reflections: 8,
            hand: seed % 2 == 0,
            placement_seed: None,
        };
        let img = render(&g, &o);
        let mask: Vec<bool> = img.ir.iter().map(|&v| v >= 20_000).collect();
        total += compare(
            &mut peer,
            &format!("rendered {seed}"),
            img.width,
            img.height,
            &mask,
        );
    }
    // Random masks: sparse specks to percolating tangles.
    let mut r = SplitMix64(99);
    for density in [0.05, 0.3, 0.45, 0.6] {
        let (w, h) = (512u32, 424u32);
        let mask: Vec<bool> = (0..w * h).map(|_| r.next_f64() < density).collect();
        total += compare(&mut peer, &format!("random {density}"), w, h, &mask);
    }
    // A checkerboard: the set pixels touch only diagonally, so with 8-connectivity they are one
    // component (with 4-connectivity they would be hundreds). Then a 1-pixel-wide image.
    let (w, h) = (37u32, 23u32);
    let checker: Vec<bool> = (0..w * h).map(|i| ((i % w) + (i / w)) % 2 == 0).collect();
    assert_eq!(compare(&mut peer, "checkerboard", w, h, &checker), 1);
    let column: Vec<bool> = (0..50).map(|i| i % 3 != 0).collect();
    compare(&mut peer, "column", 1, 50, &column);
    assert!(total > 1000, "{total} components compared");
}
