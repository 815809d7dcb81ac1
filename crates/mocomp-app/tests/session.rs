#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! A clinical session closed-loop on the stepped clock: the experiment's two simulated URs over
//! RTDE, the tracker over OpenIGTLink, both robots calibrated. The head nods while the coil walks
//! a 3 × 3 motor-mapping grid; the on-target gate drives the coil robot's digital output, a
//! simulated stimulator wired through it pulses the robot's digital input, and the session logs
//! each pulse. Then the camera is knocked by 3 mm and 1° mid-run.

use mocomp_app::experiment::{Controller, ExperimentConfig, Run, build_scene, run_experiment};
use mocomp_app::session_plan::SessionPlan;
use mocomp_control::{Event, Mode, Reason};
use mocomp_session::{GateState, GridParams, Shut};
use mocomp_sim::HeadMotion;
use mocomp_sim::motion::Nods;
use std::net::IpAddr;

/// Gentle nods, as a seated patient's: about 8 mm/s and 4°/s at their peaks.
fn nods() -> HeadMotion {
    HeadMotion::Nods(Nods {
        start_s: 0.5,
        sway_m: 0.004,
        turn_rad: 0.03,
        nod_rad: 0.02,
        frequency_hz: 0.3,
    })
}

fn session_run(coil: [u8; 4], head: [u8; 4], bump: Option<f64>) -> (ExperimentConfig, Run) {
    let mut cfg = mocomp_app::demo::experiment_config::defaults().unwrap();
    cfg.coil_host = IpAddr::from(coil);
    cfg.head_host = IpAddr::from(head);
    cfg.motion = nods();
    cfg.coil_robot = mocomp_kin::Model::Ur5e;
    cfg.head_robot = mocomp_kin::Model::Ur5e;
    cfg.set_seed(20);
    // The plan's grid around the goal the loop will have: built from the design goal here, the
    // experiment's own calibration only shifts it by its error (well under a millimetre).
    let scene = build_scene(&cfg).unwrap();
    let goal = scene.e2_from_head.inverse() * cfg.goal_e2_from_e1 * scene.e1_from_coil;
    let plan = SessionPlan::grid(&cfg.head, &goal, &GridParams::default(), 5.0, 3).unwrap();
    cfg.duration_s = plan.duration_s();
    cfg.session = Some(plan);
    // SimNIBS's Magstim D70 at 60 %: each tick's true dose, and each pulse's as measured.
    let coil = mocomp_app::config::coil::read_coil(
        &mocomp_testkit::workspace_root()
            .join("crates/mocomp-efield/tests/data/coils/MagStim_D70.ccd"),
    )
    .unwrap();
    let didt_a_per_s = 0.6 * coil.didt_max_a_per_s.unwrap();
    cfg.dose = Some(mocomp_efield::DoseModel {
        coil: std::sync::Arc::new(coil),
        didt_a_per_s,
        depth_m: 0.015,
    });
    if let Some(at) = bump {
        cfg.bump_tracker(at, 0.003, 1f64.to_radians()).unwrap();
    }
    let mut out = run_experiment(&cfg, &[Controller::Mocomp], &mut |_, _| {}).unwrap();
    (cfg, out.runs.remove(0))
}

#[test]
fn a_grid_of_nine_targets_is_walked_with_pulses_only_on_target_and_each_logged_as_it_was() {
    let (cfg, run) = session_run([127, 0, 0, 69], [127, 0, 0, 70], None);
    let plan = cfg.session.as_ref().unwrap();
    let tol = plan.params.gate;
    // Every target visited: each was selected, the loop came onto it and the gate opened.
    for i in 0..9 {
        let on = run.records.iter().filter(|r| r.target == i);
        let open = on.filter(|r| r.gate_open).count();
        assert!(open > 100, "target {i}: the gate was open for {open} ticks");
    }
    // The loop went to each by a planned path, and never pulsed on one: the gate is shut on
    // every tick the loop was not tracking.
    let approaching = run
        .records
        .iter()
        .filter(|r| r.mode == Mode::Approaching)
        .count();
    assert!(approaching > 0);
    for r in &run.records {
        if r.mode != Mode::Tracking {
            assert!(
                !r.gate_open,
                "at {:.3} s the gate was open in {:?}",
                r.t, r.mode
            );
        }
        // Open only within the tolerance: the measured error the gate judged, and the truth
        // (which it estimates within the tracker's noise and the calibration's error).
        if r.gate_open {
            assert!(
                r.measured_error.0 <= tol.position_tolerance_m
                    && r.measured_error.1 <= tol.angle_tolerance_rad,
                "at {:.3} s: {:?}",
                r.t,
                r.measured_error
            );
            assert!(
                r.target_error.0 <= tol.position_tolerance_m + 0.0005
                    && r.target_error.1 <= tol.angle_tolerance_rad + 0.2f64.to_radians(),
                "at {:.3} s the truth: {:?}",
                r.t,
                r.target_error
            );
        }
    }
    // The pulses: the gate withheld the stimulator's try during each path and let every try on
    // target through (3 per target); the ones given by hand during the paths fired all the same
    // and are logged as off target.
    let gated: Vec<_> = run.pulses.iter().filter(|p| !p.by_hand).collect();
    let by_hand: Vec<_> = run.pulses.iter().filter(|p| p.by_hand).collect();
    eprintln!(
        "{} gated pulses, {} by hand, {} withheld",
        gated.len(),
        by_hand.len(),
        run.withheld_pulses
    );
    assert_eq!(run.withheld_pulses, 9);
    assert_eq!(gated.len(), 27);
    assert_eq!(by_hand.len(), 9);
    for p in &by_hand {
        assert!(
            matches!(p.pulse.gate, GateState::Shut(Shut::NotTracking)),
            "{p:?}"
        );
    }
    let mut worst = (0.0f64, 0.0f64);
    for p in &gated {
        assert_eq!(p.pulse.gate, GateState::Open, "{p:?}");
        let target = plan.target_at(p.pulse.t_s);
        assert_eq!(p.pulse.target, target);
        // The log's error is the truth's within the tracker's noise (0.1 mm per axis, filtered)
        // and the calibration's error.
        let d = (p.pulse.position_error_m - p.truth.0).abs();
        let a = (p.pulse.angle_error_rad - p.truth.1).abs();
        worst = (worst.0.max(d), worst.1.max(a));
        assert!(p.pulse.position_error_m <= tol.position_tolerance_m);
        assert!(p.pulse.head_speed.0 > 0.0);
    }
    eprintln!(
        "pulse log against the truth: worst {:.3} mm, {:.3} deg",
        worst.0 * 1e3,
        worst.1.to_degrees()
    );
    // Each pulse's dose, as the loop measured it (the measured coil against its target's
    // plan), is the true coil's at that tick within what the tracker's noise and the
    // calibration's error move the coil by (a quarter of a millimetre's lift is 1 %).
    let mut dose_worst = (0.0f64, 0.0f64);
    for p in &gated {
        let tick = run
            .records
            .iter()
            .min_by(|a, b| {
                (a.t - p.pulse.t_s)
                    .abs()
                    .total_cmp(&(b.t - p.pulse.t_s).abs())
            })
            .unwrap();
        let (measured, truth) = (p.pulse.dose.1, tick.dose_pct);
        assert!(measured.is_finite() && truth.is_finite(), "{p:?} {truth}");
        assert!(
            p.pulse.dose.0 > 20.0 && p.pulse.dose.0 < 400.0,
            "{} V/m",
            p.pulse.dose.0
        );
        dose_worst = (
            dose_worst.0.max((measured - truth).abs()),
            dose_worst.1.max((truth - 100.0).abs()),
        );
    }
    eprintln!(
        "pulse doses: measured against the truth worst {:.3} %; the truth's worst {:.3} % off \
         the planned",
        dose_worst.0, dose_worst.1
    );
    assert!(dose_worst.0 < 1.5, "{dose_worst:?}");
    assert!(
        worst.0 < 0.5e-3 && worst.1 < 0.3f64.to_radians(),
        "{worst:?}"
    );
    // Nothing held the loop: no drift alarm on a still camera.
    assert!(
        !run.records
            .iter()
            .any(|r| matches!(r.event, Some(Event::Hold(Reason::CalibrationInvalid(..))))),
    );
}

#[test]
fn a_camera_knocked_by_3_mm_and_1_degree_is_caught_within_half_a_second_and_the_loop_holds() {
    let (_, run) = session_run([127, 0, 0, 71], [127, 0, 0, 72], Some(12.0));
    let after = run.bump_detected_after_s.expect("detected");
    eprintln!("bump detected after {after:.3} s");
    assert!(after < 0.5, "{after}");
    // The loop holds with the reason and the offset from then on, and the gate stays shut.
    let held = run
        .records
        .iter()
        .find(|r| matches!(r.event, Some(Event::Hold(Reason::CalibrationInvalid(..)))))
        .expect("a hold for the calibration");
    assert!(held.t >= 12.0 && held.t < 12.5 + 0.01, "{}", held.t);
    if let Some(Event::Hold(Reason::CalibrationInvalid(m, a))) = held.event {
        assert!(m > 0.002 || a > 0.8f64.to_radians(), "{m} {a}");
    }
    for r in run.records.iter().filter(|r| r.t > held.t) {
        assert!(
            matches!(r.mode, Mode::Holding(Reason::CalibrationInvalid(..))),
            "at {:.3} s: {:?}",
            r.t,
            r.mode
        );
        assert!(!r.gate_open);
    }
    // No gated pulse after the knock.
    assert!(
        run.pulses
            .iter()
            .filter(|p| !p.by_hand)
            .all(|p| p.pulse.t_s < held.t)
    );
}
