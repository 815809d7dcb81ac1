//! The pipeline on rendered sequences with known ground truth: pose error statistics at
//! Kinect-like noise, with distractors, with a fiducial hidden; Kabsch against the seed paper's
//! three-point frame; frames without markers; bad input.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{rotation_error, translation_error};
use mocomp_vision::params::Registration;
use mocomp_vision::render::{Distractors, RenderOptions, render, view_pose};
use mocomp_vision::{Frame, MarkerGeometry, NotFound, TrackParams, Tracker, VisionError};

/// NDI 8700449's layout: distances 50.0–89.1 mm, gaps ≥ 5 mm.
fn geometry() -> MarkerGeometry {
    MarkerGeometry::ndi_8700449()
}

struct Stats {
    found: usize,
    total: usize,
    t_mm: Vec<f64>,
    r_deg: Vec<f64>,
}

impl Stats {
    fn pct(v: &[f64], p: f64) -> f64 {
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        s[((s.len() - 1) as f64 * p).round() as usize]
    }
    fn rms(v: &[f64]) -> f64 {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }
    fn line(&self, what: &str) -> String {
        format!(
            "{what}: found {}/{}; translation median {:.2} mm, p95 {:.2} mm; rotation median {:.2}°, p95 {:.2}°",
            self.found,
            self.total,
            Self::pct(&self.t_mm, 0.5),
            Self::pct(&self.t_mm, 0.95),
            Self::pct(&self.r_deg, 0.5),
            Self::pct(&self.r_deg, 0.95)
        )
    }
}

fn run(
    n: usize,
    seed: u64,
    params: TrackParams,
    tweak: impl Fn(&mut RenderOptions, usize),
) -> Stats {
    let g = geometry();
    let mut tracker =
        Tracker::new(mocomp_vision::Intrinsics::kinect_v2(), params, g.clone()).unwrap();
    let mut s = Stats {
        found: 0,
        total: 0,
        t_mm: vec![],
        r_deg: vec![],
    };
    for i in 0..n {
        let truth = view_pose(seed * 100_000 + i as u64);
        let mut o = RenderOptions::kinect(truth, seed * 1000 + i as u64);
        tweak(&mut o, i);
        let img = render(&g, &o);
        let frame = Frame::new(img.width, img.height, &img.ir, &img.depth).unwrap();
        let res = tracker.process(&frame).unwrap();
        s.total += 1;
        if let Some(d) = res.detection {
            s.found += 1;
            s.t_mm
                .push(translation_error(&d.tracker_from_marker, &truth) * 1e3);
            s.r_deg
                .push(rotation_error(&d.tracker_from_marker, &truth).to_degrees());
        }
    }
    s
}

#[test]
fn clean_sequence_is_tracked_accurately() {
    let s = run(200, 1, TrackParams::default(), |_, _| {});
    println!("{}", s.line("clean"));
    assert!(s.found >= 198, "{}", s.line("clean"));
    assert!(
        Stats::pct(&s.t_mm, 0.5) < 1.5 && Stats::pct(&s.t_mm, 0.95) < 4.0,
        "{}",
        s.line("clean")
    );
    assert!(
        Stats::pct(&s.r_deg, 0.5) < 1.0 && Stats::pct(&s.r_deg, 0.95) < 2.5,
        "{}",
        s.line("clean")
    );
}

#[test]
fn distractors_do_not_break_tracking() {
    let s = run(200, 2, TrackParams::default(), |o, i| {
        o.distractors = Distractors {
            sun_spots: 2,
            reflections: 6,
            hand: i % 4 == 0,
            placement_seed: None,
        };
    });
    println!("{}", s.line("distractors"));
    assert!(s.found >= 180, "{}", s.line("distractors"));
    assert!(
        Stats::pct(&s.t_mm, 0.5) < 1.5 && Stats::pct(&s.t_mm, 0.95) < 4.0,
        "{}",
        s.line("distractors")
    );
    // Nothing wild: every pose found is within a centimetre.
    assert!(
        s.t_mm.iter().all(|e| *e < 10.0),
        "{}",
        s.line("distractors")
    );
}

#[test]
fn one_hidden_fiducial_is_tolerated() {
    let s = run(200, 3, TrackParams::default(), |o, i| {
        o.hidden = vec![i % 4]
    });
    println!("{}", s.line("one hidden"));
    assert!(s.found >= 196, "{}", s.line("one hidden"));
    assert!(
        Stats::pct(&s.t_mm, 0.5) < 2.0 && Stats::pct(&s.t_mm, 0.95) < 5.0,
        "{}",
        s.line("one hidden")
    );
    // Two hidden of four: not found (only 2 left), never a wrong pose.
    let s = run(40, 4, TrackParams::default(), |o, i| {
        o.hidden = vec![i % 4, (i + 1) % 4]
    });
    assert_eq!(s.found, 0);
}

#[test]
fn kabsch_beats_the_three_point_frame() {
    let kabsch = run(200, 5, TrackParams::default(), |_, _| {});
    let three = run(
        200,
        5,
        TrackParams {
            registration: Registration::ThreePoint,
            max_fre_mm: 50.0,
            ..TrackParams::default()
        },
        |_, _| {},
    );
    println!("{}\n{}", kabsch.line("kabsch"), three.line("three-point"));
    assert!(Stats::rms(&kabsch.t_mm) < Stats::rms(&three.t_mm));
    assert!(Stats::rms(&kabsch.r_deg) < Stats::rms(&three.r_deg));
}

#[test]
fn frames_without_markers_are_not_found_not_errors() {
    let g = geometry();
    let mut tracker = Tracker::new(
        mocomp_vision::Intrinsics::kinect_v2(),
        TrackParams::default(),
        g.clone(),
    )
    .unwrap();
    // A blank scene: the marker is behind the camera.
    let behind = Isometry3::translation(0.0, 0.0, -1.0);
    let img = render(&g, &RenderOptions::kinect(behind, 7));
    let res = tracker
        .process(&Frame::new(img.width, img.height, &img.ir, &img.depth).unwrap())
        .unwrap();
    assert!(res.detection.is_none());
    assert!(matches!(
        res.not_found,
        Some(NotFound::TooFewBlobs { candidates: 0, .. })
    ));
    // Only distractors.
    let mut o = RenderOptions::kinect(behind, 8);
    o.distractors = Distractors {
        sun_spots: 3,
        reflections: 10,
        hand: true,
        placement_seed: None,
    };
    let img = render(&g, &o);
    let res = tracker
        .process(&Frame::new(img.width, img.height, &img.ir, &img.depth).unwrap())
        .unwrap();
    assert!(res.detection.is_none(), "{:?}", res.not_found);
    assert!(res.not_found.unwrap().to_string().len() > 10);
}

#[test]
fn frames_of_the_wrong_size_are_errors() {
    let g = geometry();
    let mut tracker = Tracker::new(
        mocomp_vision::Intrinsics::kinect_v2(),
        TrackParams::default(),
        g,
    )
    .unwrap();
    let ir = vec![0u16; 640 * 576];
    let f = Frame::new(640, 576, &ir, &ir).unwrap();
    let e = tracker.process(&f).unwrap_err();
    assert!(matches!(e, VisionError::SizeMismatch { .. }), "{e}");
    assert!(e.to_string().contains("640×576") && e.to_string().contains("512×424"));
}
