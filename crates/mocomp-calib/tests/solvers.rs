//! The solvers on seeded synthetic data: exact recovery without noise, accuracy with noise,
//! uncertainty estimates that match the observed errors, degenerate sets named, outliers found.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_calib::error::CalibError;
use mocomp_calib::synth::{SynthOptions, synthesize};
use mocomp_calib::{CalibrationFile, Method, NoiseModel, Pair, SolveOptions, linear, solve};
use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use mocomp_geom::{quat_from_rotvec, rotation_error, translation_error};

fn exact(count: usize, seed: u64) -> (SynthOptions, Vec<Pair>) {
    let o = SynthOptions {
        count,
        noise: None,
        seed,
        ..SynthOptions::default()
    };
    let p = synthesize(&o).unwrap();
    (o, p)
}

fn noisy(count: usize, seed: u64) -> (SynthOptions, Vec<Pair>) {
    let o = SynthOptions {
        count,
        seed,
        ..SynthOptions::default()
    };
    let p = synthesize(&o).unwrap();
    (o, p)
}

fn opts(method: Method) -> SolveOptions {
    SolveOptions {
        method,
        ..SolveOptions::default()
    }
}

#[test]
fn noise_free_data_is_recovered_to_1e9_by_every_solver() {
    for (count, seed) in [(3, 1), (5, 2), (20, 3), (100, 4)] {
        let (o, pairs) = exact(count, seed);
        for method in [Method::Li, Method::Shah, Method::Refined] {
            let c = solve(&pairs, &opts(method)).unwrap();
            let ex = (
                translation_error(&c.flange_from_marker, &o.flange_from_marker),
                rotation_error(&c.flange_from_marker, &o.flange_from_marker),
            );
            let ey = (
                translation_error(&c.base_from_tracker, &o.base_from_tracker),
                rotation_error(&c.base_from_tracker, &o.base_from_tracker),
            );
            assert!(
                ex.0 < 1e-9 && ex.1 < 1e-9 && ey.0 < 1e-9 && ey.1 < 1e-9,
                "{method} N={count}: X off by {ex:?}, Y off by {ey:?}"
            );
            assert!(c.rms_mm < 1e-6 && c.max_deg < 1e-6);
            assert!(c.outliers.is_empty());
        }
        // The li variant without the translation re-solve is exact too.
        let (x, y) = linear::li(&pairs, false).unwrap();
        assert!(translation_error(&x, &o.flange_from_marker) < 1e-9);
        assert!(translation_error(&y, &o.base_from_tracker) < 1e-9);
    }
}

fn errors(c: &mocomp_calib::Calibration, o: &SynthOptions) -> (f64, f64, f64, f64) {
    (
        rotation_error(&c.flange_from_marker, &o.flange_from_marker).to_degrees(),
        translation_error(&c.flange_from_marker, &o.flange_from_marker) * 1e3,
        rotation_error(&c.base_from_tracker, &o.base_from_tracker).to_degrees(),
        translation_error(&c.base_from_tracker, &o.base_from_tracker) * 1e3,
    )
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn with_noise_refined_beats_the_closed_forms_and_resolve_helps_li() {
    let trials = 40;
    let mut y_mm = [vec![], vec![], vec![], vec![]];
    for seed in 0..trials {
        let (o, pairs) = noisy(20, 100 + seed);
        for (k, method) in [Method::Li, Method::Shah, Method::Refined]
            .into_iter()
            .enumerate()
        {
            let c = solve(&pairs, &opts(method)).unwrap();
            y_mm[k].push(errors(&c, &o).3);
        }
        let (_, y) = linear::li(&pairs, false).unwrap();
        y_mm[3].push(translation_error(&y, &o.base_from_tracker) * 1e3);
    }
    let [li, shah, refined, li_raw] = y_mm.map(median);
    println!(
        "median Y translation error (mm), N=20: li {li:.3}, li without re-solve {li_raw:.3}, shah {shah:.3}, refined {refined:.3}"
    );
    assert!(
        refined * 3.0 < li.min(shah),
        "refined {refined} vs li {li}, shah {shah}"
    );
    assert!(
        li < li_raw,
        "re-solving translations helps: {li} vs {li_raw}"
    );
}

#[test]
fn uncertainty_matches_the_observed_error() {
    // Over 40 trials, the RMS of the actual errors should be close to the predicted 1σ.
    let mut pred = [0.0; 4];
    let mut seen = [0.0; 4];
    let trials = 40;
    for seed in 0..trials {
        let (o, pairs) = noisy(30, 500 + seed);
        let c = solve(&pairs, &SolveOptions::default()).unwrap();
        let e = errors(&c, &o);
        let u = c.uncertainty;
        let p = [
            u.x_rotation_deg,
            u.x_translation_mm,
            u.y_rotation_deg,
            u.y_translation_mm,
        ];
        for k in 0..4 {
            pred[k] += p[k] * p[k] / trials as f64;
            seen[k] += [e.0, e.1, e.2, e.3][k].powi(2) / trials as f64;
        }
    }
    for k in 0..4 {
        let ratio = seen[k].sqrt() / pred[k].sqrt();
        assert!(
            (0.6..1.6).contains(&ratio),
            "quantity {k}: observed RMS {:.4} vs predicted 1σ {:.4}",
            seen[k].sqrt(),
            pred[k].sqrt()
        );
    }
}

#[test]
fn degenerate_sets_are_named() {
    // Fewer than 3.
    let (_, pairs) = exact(2, 1);
    assert_eq!(
        solve(&pairs, &SolveOptions::default()).unwrap_err(),
        CalibError::TooFewPairs { found: 2 }
    );

    // Rotations about one axis only (the flange turning about its own z).
    let o = SynthOptions::default();
    let pairs: Vec<Pair> = (0..8)
        .map(|i| {
            let turn = Isometry3::from_parts(
                Translation3::new(0.01 * i as f64, 0.0, 0.0),
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.2 * i as f64),
            );
            let m = o.center * turn;
            Pair::new(m, o.base_from_tracker.inverse() * m * o.flange_from_marker)
        })
        .collect();
    let err = solve(&pairs, &SolveOptions::default()).unwrap_err();
    assert!(matches!(err, CalibError::SingleAxis { .. }), "{err}");
    assert!(err.to_string().contains("two different axes"));

    // Tiny rotations.
    let small = SynthOptions {
        rotation_range_rad: (0.5f64.to_radians(), 1.5f64.to_radians()),
        ..SynthOptions::default()
    };
    let err = solve(&synthesize(&small).unwrap(), &SolveOptions::default()).unwrap_err();
    assert!(matches!(err, CalibError::RotationsTooSmall { .. }), "{err}");

    // A duplicate robot pose (a repeated log line), named by pair number and line.
    let (_, mut pairs) = noisy(10, 3);
    pairs[7] = pairs[2];
    pairs[2].line = Some(4);
    pairs[7].line = Some(9);
    let err = solve(&pairs, &SolveOptions::default()).unwrap_err();
    assert!(matches!(err, CalibError::DuplicatePoses { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.contains("pair 3 (line 4)") && text.contains("pair 8 (line 9)"),
        "{text}"
    );

    // A non-finite measurement.
    let (_, mut pairs) = exact(5, 1);
    pairs[1].tracker_from_marker.translation.x = f64::NAN;
    assert!(matches!(
        solve(&pairs, &SolveOptions::default()).unwrap_err(),
        CalibError::NonFinite { .. }
    ));
}

#[test]
fn a_marker_that_slips_halfway_is_not_rigid() {
    let (o, mut pairs) = noisy(30, 9);
    // From pair 15 on, the marker sits 2 cm and 10° differently on the flange.
    let slipped = o.flange_from_marker
        * Isometry3::from_parts(
            Translation3::new(0.02, 0.0, 0.0),
            quat_from_rotvec(&Vector3::new(0.0, 0.17, 0.0)),
        );
    for p in pairs.iter_mut().skip(15) {
        p.tracker_from_marker = o.base_from_tracker.inverse() * p.base_from_flange * slipped;
    }
    let err = solve(&pairs, &SolveOptions::default()).unwrap_err();
    assert!(matches!(err, CalibError::NonRigid { .. }), "{err}");
    assert!(
        err.to_string().contains("the robot rotated")
            || err.to_string().contains("along its rotation axis"),
        "{err}"
    );
}

#[test]
fn outlier_pairs_are_found_reported_and_left_out_on_request() {
    let (o, mut pairs) = noisy(30, 21);
    let clean = solve(&pairs, &SolveOptions::default()).unwrap();
    // Two pairs where the tracker read the marker 8 mm off.
    for i in [4, 17] {
        pairs[i].tracker_from_marker.translation.vector += Vector3::new(0.008, 0.0, -0.002);
    }
    let robust = solve(&pairs, &SolveOptions::default()).unwrap();
    assert_eq!(robust.outliers, vec![4, 17]);
    assert!(robust.residuals[4].outlier && robust.residuals[4].used);
    let rejected = solve(
        &pairs,
        &SolveOptions {
            reject_outliers: true,
            ..SolveOptions::default()
        },
    )
    .unwrap();
    assert_eq!(rejected.outliers, vec![4, 17]);
    assert!(!rejected.residuals[4].used && !rejected.residuals[17].used);
    let e_clean = errors(&clean, &o).3;
    let e_rej = errors(&rejected, &o).3;
    let e_robust = errors(&robust, &o).3;
    let li = solve(&pairs, &opts(Method::Li)).unwrap();
    let e_li = errors(&li, &o).3;
    assert!(
        e_rej < 2.0 * e_clean + 0.05,
        "rejected {e_rej} vs clean {e_clean}"
    );
    assert!(e_robust < e_li, "Huber-weighted {e_robust} vs li {e_li}");
    // The statistics cover the pairs used.
    assert!(rejected.max_mm < 2.0, "{}", rejected.max_mm);
}

#[test]
fn result_file_round_trips_and_rejects_unknown_keys() {
    let (_, pairs) = noisy(20, 5);
    let c = solve(&pairs, &SolveOptions::default()).unwrap();
    let text = c.to_file().to_toml_string().unwrap();
    assert!(text.contains("[X]") && text.contains("[Y]"), "{text}");
    let back = CalibrationFile::from_toml_str(&text).unwrap();
    let (x, y) = back.transforms().unwrap();
    assert!(translation_error(&x, &c.flange_from_marker) < 1e-15);
    assert!(rotation_error(&y, &c.base_from_tracker) < 1e-14);
    let bad = text.replace("method =", "methd =");
    assert!(
        CalibrationFile::from_toml_str(&bad)
            .unwrap_err()
            .to_string()
            .contains("methd")
    );
}

#[test]
fn noise_model_must_be_positive() {
    let (_, pairs) = exact(5, 1);
    let o = SolveOptions {
        noise: NoiseModel::from_mm_deg(0.0, 0.1, 0.03, 0.01),
        ..SolveOptions::default()
    };
    assert!(
        solve(&pairs, &o)
            .unwrap_err()
            .to_string()
            .contains("tracker translation noise")
    );
}
