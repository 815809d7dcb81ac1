//! Interop: our calibration solvers against OpenCV's `calibrateRobotWorldHandEye` (SHAH and LI,
//! from `opencv-python-headless` 4.14) on the same seeded synthetic sets.
//!
//! Noise-free, every method recovers the truth (which also checks the frame mapping between
//! OpenCV's world/camera/gripper and our X/Y). With tracker noise 0.1 mm / 0.1° and robot noise
//! 0.03 mm / 0.01°, `refined` must be at least 3× more accurate than OpenCV's better method on the
//! translation of Y, at N = 10, 20, 50 and 200, over 40 trials each.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_calib::synth::{SynthOptions, synthesize};
use mocomp_calib::{Method, Pair, SolveOptions, solve};
use mocomp_geom::nalgebra::{Isometry3, Matrix4};
use mocomp_geom::{iso_from_matrix, rotation_error, rows_from_iso, translation_error};
use mocomp_testkit::PythonPeer;
use serde_json::{Value, json};

fn opencv() -> PythonPeer {
    PythonPeer::start("opencv_handeye_peer.py", "opencv-python-headless", "4.14.0")
}

fn set_json(pairs: &[Pair]) -> Value {
    json!({
        "base_from_flange": pairs.iter().map(|p| rows_from_iso(&p.base_from_flange)).collect::<Vec<_>>(),
        "tracker_from_marker": pairs.iter().map(|p| rows_from_iso(&p.tracker_from_marker)).collect::<Vec<_>>(),
    })
}

fn transform(v: &Value) -> Isometry3<f64> {
    let m = Matrix4::from_fn(|r, c| v[r][c].as_f64().unwrap());
    iso_from_matrix(&m, 1e-6).unwrap()
}

/// OpenCV's (X, Y) for each set.
fn opencv_solve(
    peer: &mut PythonPeer,
    method: &str,
    sets: &[Vec<Pair>],
) -> Vec<(Isometry3<f64>, Isometry3<f64>)> {
    let req = json!({"op": "calibrate", "method": method, "sets": sets.iter().map(|s| set_json(s)).collect::<Vec<_>>()});
    let v = peer.request(&req);
    v["results"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (transform(&r["X"]), transform(&r["Y"])))
        .collect()
}

#[test]
fn noise_free_every_method_recovers_the_truth() {
    let mut peer = opencv();
    let mut truths = Vec::new();
    let mut sets = Vec::new();
    for (count, seed) in [(5, 1), (20, 2), (50, 3)] {
        let o = SynthOptions {
            count,
            seed,
            noise: None,
            ..SynthOptions::default()
        };
        sets.push(synthesize(&o).unwrap());
        truths.push(o);
    }
    for method in ["SHAH", "LI"] {
        for ((x, y), o) in opencv_solve(&mut peer, method, &sets).iter().zip(&truths) {
            assert!(
                translation_error(x, &o.flange_from_marker) < 1e-6,
                "OpenCV {method} X"
            );
            assert!(
                rotation_error(x, &o.flange_from_marker) < 1e-6,
                "OpenCV {method} X"
            );
            assert!(
                translation_error(y, &o.base_from_tracker) < 1e-6,
                "OpenCV {method} Y"
            );
            assert!(
                rotation_error(y, &o.base_from_tracker) < 1e-6,
                "OpenCV {method} Y"
            );
        }
    }
    for (pairs, o) in sets.iter().zip(&truths) {
        for method in [Method::Li, Method::Shah, Method::Refined] {
            let c = solve(
                pairs,
                &SolveOptions {
                    method,
                    ..SolveOptions::default()
                },
            )
            .unwrap();
            assert!(translation_error(&c.base_from_tracker, &o.base_from_tracker) < 1e-9);
            assert!(rotation_error(&c.flange_from_marker, &o.flange_from_marker) < 1e-9);
        }
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn refined_is_three_times_more_accurate_than_opencv_on_y_translation() {
    let mut peer = opencv();
    let trials = 40u64;
    let mut lines = Vec::new();
    for count in [10usize, 20, 50, 200] {
        let mut truths = Vec::new();
        let mut sets = Vec::new();
        for t in 0..trials {
            let o = SynthOptions {
                count,
                seed: 10_000 * count as u64 + t,
                ..SynthOptions::default()
            };
            sets.push(synthesize(&o).unwrap());
            truths.push(o);
        }
        let y_err = |sol: &[(Isometry3<f64>, Isometry3<f64>)]| {
            median(
                sol.iter()
                    .zip(&truths)
                    .map(|((_, y), o)| translation_error(y, &o.base_from_tracker) * 1e3)
                    .collect(),
            )
        };
        let shah = y_err(&opencv_solve(&mut peer, "SHAH", &sets));
        let li = y_err(&opencv_solve(&mut peer, "LI", &sets));
        let ours: Vec<(Isometry3<f64>, Isometry3<f64>)> = sets
            .iter()
            .map(|s| {
                let c = solve(s, &SolveOptions::default()).unwrap();
                (c.flange_from_marker, c.base_from_tracker)
            })
            .collect();
        let refined = y_err(&ours);
        let best = shah.min(li);
        lines.push(format!(
            "N={count:>3}: median Y translation error: OpenCV SHAH {shah:.3} mm, LI {li:.3} mm; refined {refined:.3} mm ({:.1}× better)",
            best / refined
        ));
        assert!(
            refined * 3.0 <= best,
            "N={count}: refined {refined:.3} mm is not 3× better than OpenCV's {best:.3} mm\n{}",
            lines.join("\n")
        );
    }
    println!("{}", lines.join("\n"));
}
