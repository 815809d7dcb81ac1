//! The calibration pose planner: reachable on one branch, spread, visible, short, and good enough
//! to calibrate from.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_calib::error::CalibError;
use mocomp_calib::plan::{PlanOptions, TrackerView, plan, start_at_center, tour_time};
use mocomp_calib::{Pair, SolveOptions, solve};
use mocomp_geom::nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use mocomp_geom::{quat_from_rotvec, rotation_error, rotvec_from_quat, translation_error};
use mocomp_kin::{Arm, BranchCoordinates, Model};

struct Setup {
    arm: Arm,
    current: [f64; 6],
    center: Isometry3<f64>,
    x: Isometry3<f64>,
    y: Isometry3<f64>,
}

/// A UR3 with a marker 10 cm out on the flange and a tracker 1.4 m in front of the marker.
fn setup() -> Setup {
    let arm = Arm::new(Model::Ur3);
    let current = [0.3, -1.3, 1.5, -1.6, -1.4, 0.2];
    let center = arm.fk_flange(&current);
    let x = Isometry3::from_parts(
        Translation3::new(0.0, 0.03, 0.10),
        quat_from_rotvec(&Vector3::new(0.3, 0.0, 0.0)),
    );
    let marker = center * x;
    let normal = marker.rotation * Vector3::z();
    let eye = marker.translation.vector + normal * 1.4;
    // Tracker +z looks back at the marker.
    let rot = UnitQuaternion::face_towards(&(-normal), &Vector3::z());
    let y = Isometry3::from_parts(Translation3::from(eye), rot);
    Setup {
        arm,
        current,
        center,
        x,
        y,
    }
}

fn options(s: &Setup, count: usize) -> PlanOptions {
    let mut o = PlanOptions::new(count, s.center, s.current);
    o.flange_from_marker = s.x;
    o.tracker = Some(TrackerView::typical(s.y));
    o
}

#[test]
fn planned_poses_are_reachable_spread_and_visible() {
    let s = setup();
    assert!(
        TrackerView::typical(s.y).sees(&(s.center * s.x)),
        "setup: marker visible at the centre"
    );
    let poses = plan(&s.arm, &options(&s, 20)).unwrap();
    assert_eq!(poses.len(), 20);
    let branch = BranchCoordinates::of(s.arm.geometry(), &s.current).branch();
    let mut scatter = Matrix3::zeros();
    for p in &poses {
        let back = s.arm.fk_flange(&p.joints);
        assert!(translation_error(&back, &p.base_from_flange) < 1e-9);
        assert!(rotation_error(&back, &p.base_from_flange) < 1e-9);
        assert_eq!(
            BranchCoordinates::of(s.arm.geometry(), &p.joints).branch(),
            branch
        );
        assert!(s.arm.limits().contains(&p.joints, 0.1));
        let angle = rotation_error(&s.center, &p.base_from_flange).to_degrees();
        assert!(
            (14.99..=40.01).contains(&angle),
            "rotation {angle}° from the centre"
        );
        assert!(TrackerView::typical(s.y).sees(&(p.base_from_flange * s.x)));
        let w = rotvec_from_quat(&(s.center.rotation.inverse() * p.base_from_flange.rotation));
        scatter += w * w.transpose();
    }
    // Rotations over several axes: all three eigenvalues of the scatter are substantial.
    let mut ev: Vec<f64> = scatter
        .symmetric_eigen()
        .eigenvalues
        .iter()
        .copied()
        .collect();
    ev.sort_by(f64::total_cmp);
    assert!(ev[0] / ev[2] > 0.1, "axis spread {ev:?}");
    // Distinct poses.
    for i in 0..poses.len() {
        for j in i + 1..poses.len() {
            assert!(rotation_error(&poses[i].base_from_flange, &poses[j].base_from_flange) > 1e-3);
        }
    }
}

#[test]
fn the_tour_is_shorter_than_shuffled_orders() {
    let s = setup();
    let poses = plan(&s.arm, &options(&s, 20)).unwrap();
    let planned = tour_time(&s.arm, &s.current, &poses);
    let mut state = 99u64;
    for _ in 0..10 {
        let mut shuffled = poses.clone();
        for i in (1..shuffled.len()).rev() {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let j = (state >> 33) as usize % (i + 1);
            shuffled.swap(i, j);
        }
        assert!(planned < tour_time(&s.arm, &s.current, &shuffled));
    }
}

#[test]
fn an_unreachable_centre_says_why() {
    let s = setup();
    let mut o = options(&s, 10);
    o.center = Isometry3::translation(2.0, 0.0, 0.3);
    o.tracker = None;
    match plan(&s.arm, &o) {
        Err(CalibError::PlanShort {
            found, unreachable, ..
        }) => {
            assert_eq!(found, 0);
            assert!(unreachable > 0);
        }
        other => panic!("expected PlanShort, got {other:?}"),
    }
    let mut o = options(&s, 10);
    o.rotation_range_rad = (0.0, 0.5);
    assert!(matches!(
        plan(&s.arm, &o),
        Err(CalibError::InvalidOption(_))
    ));
}

#[test]
fn a_planned_run_calibrates_well() {
    let s = setup();
    let poses = plan(&s.arm, &options(&s, 20)).unwrap();
    // Measure: exact robot, tracker with a small deterministic disturbance.
    let pairs: Vec<Pair> = poses
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let k = i as f64;
            let wobble = Isometry3::from_parts(
                Translation3::new(
                    1e-4 * (k * 1.3).sin(),
                    1e-4 * (k * 2.1).cos(),
                    1e-4 * (k * 0.7).sin(),
                ),
                quat_from_rotvec(&Vector3::new(
                    1e-3 * (k * 1.1).cos(),
                    1e-3 * (k * 0.3).sin(),
                    0.0,
                )),
            );
            Pair::new(
                p.base_from_flange,
                s.y.inverse() * p.base_from_flange * s.x * wobble,
            )
        })
        .collect();
    let c = solve(&pairs, &SolveOptions::default()).unwrap();
    assert!(translation_error(&c.base_from_tracker, &s.y) < 1e-3);
    assert!(translation_error(&c.flange_from_marker, &s.x) < 5e-4);
}

#[test]
fn without_current_joints_the_plan_starts_at_the_centre_or_says_it_cannot() {
    let s = setup();
    let q = start_at_center(&s.arm, &s.center).unwrap();
    let at = s.arm.fk_flange(&q);
    assert!(translation_error(&at, &s.center) < 1e-9);
    assert!(rotation_error(&at, &s.center) < 1e-9);
    // 3 m away: out of a UR3's reach, named.
    let far = Isometry3::translation(3.0, 0.0, 0.0) * s.center;
    let e = start_at_center(&s.arm, &far).unwrap_err();
    assert!(
        matches!(&e, CalibError::InvalidOption(m) if m.contains("not reachable")),
        "{e}"
    );
}
