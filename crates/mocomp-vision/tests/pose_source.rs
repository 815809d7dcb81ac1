//! The vision `PoseSource`: newest frame wins, timestamps are the acquisition times, lost markers
//! give invalid samples carrying the last pose, bad frames are counted, not fatal.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{PoseSource, translation_error};
use mocomp_vision::render::{RenderOptions, render, view_pose};
use mocomp_vision::source::{TimedFrame, VisionPoseSource};
use mocomp_vision::{Intrinsics, MarkerGeometry, TrackParams, Tracker};
use std::collections::VecDeque;

fn geometry() -> MarkerGeometry {
    MarkerGeometry::ndi_8700449()
}

fn frame(pose: Isometry3<f64>, seed: u64, t: f64) -> TimedFrame {
    let img = render(&geometry(), &RenderOptions::kinect(pose, seed));
    TimedFrame {
        width: img.width,
        height: img.height,
        ir: img.ir,
        depth: img.depth,
        acquired_s: t,
    }
}

#[test]
fn samples_follow_the_newest_frame() {
    let tracker =
        || Tracker::new(Intrinsics::kinect_v2(), TrackParams::default(), geometry()).unwrap();
    let (a, b) = (view_pose(1), view_pose(2));
    let mut src = VisionPoseSource::new(tracker(), VecDeque::new());
    assert!(src.latest().is_none(), "no frame, no sample");
    let queued = VecDeque::from(vec![frame(a, 1, 10.0), frame(b, 2, 10.033)]);
    let mut src = VisionPoseSource::new(tracker(), queued);
    let s = src.latest().unwrap();
    assert!(s.valid);
    assert_eq!(s.acquired_s, 10.033, "the newest frame's acquisition time");
    assert!(translation_error(&s.tracker_from_marker, &b) < 0.003);
    assert!(s.error_m < 0.004);
    assert_eq!(src.counters().skipped, 1);
    assert!(src.latest().is_none());
}

#[test]
fn lost_marker_and_bad_frames() {
    let tracker =
        Tracker::new(Intrinsics::kinect_v2(), TrackParams::default(), geometry()).unwrap();
    let a = view_pose(3);
    let (tx, rx) = std::sync::mpsc::channel();
    let mut src = VisionPoseSource::new(tracker, rx);
    tx.send(frame(a, 3, 1.0)).unwrap();
    let first = src.latest().unwrap();
    assert!(first.valid);
    // The marker leaves the view: an invalid sample with the last pose.
    tx.send(frame(Isometry3::translation(0.0, 0.0, -1.0), 4, 1.1))
        .unwrap();
    let lost = src.latest().unwrap();
    assert!(!lost.valid);
    assert_eq!(lost.tracker_from_marker, first.tracker_from_marker);
    assert!(lost.error_m.is_nan());
    // A frame of the wrong size is counted and reported, not fatal.
    tx.send(TimedFrame {
        width: 10,
        height: 10,
        ir: vec![0; 100],
        depth: vec![0; 100],
        acquired_s: 1.2,
    })
    .unwrap();
    assert!(src.latest().is_none());
    assert_eq!(src.counters().rejected, 1);
    assert!(src.last_error().unwrap().to_string().contains("10×10"));
    tx.send(frame(a, 5, 1.3)).unwrap();
    assert!(src.latest().unwrap().valid);
    assert_eq!(src.counters().found, 2);
}
