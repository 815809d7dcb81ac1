//! The coil as its casing (SimNIBS's Magstim D70 `.stl`, 200 mm from wing to wing) in the
//! loop's clearance and goal check, on the built-in world's ellipsoid: its clearance is the
//! casing's (checked against points laid over the hull every millimetre, no GJK), never
//! more room below a cutoff, and a goal the old 40 × 30 mm cylinder clears while a wing of the
//! casing cuts the head is refused.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_control::geometry::ellipsoid_distance;
use mocomp_control::{CoilModel, GoalError, HeadModel, check_goal};
use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_head::HeadShape;
use mocomp_head::casing::Casing;
use mocomp_testkit::SplitMix64;
use std::sync::Arc;

fn d70() -> Arc<Casing> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../mocomp-efield/tests/data/coils/MagStim_D70.stl");
    let bytes = std::fs::read(&path).unwrap();
    Arc::new(
        mocomp_head::formats::read_casing("MagStim_D70.stl", &bytes, LengthUnit::Millimetre)
            .unwrap(),
    )
}

fn with_casing(casing: &Arc<Casing>) -> CoilModel {
    CoilModel {
        casing: Some(Arc::clone(casing)),
        ..CoilModel::cylinder(0.04, 0.03)
    }
}

/// Points on the hull's triangles about `step` m apart (coil frame).
fn hull_points(casing: &Casing, step: f64) -> Vec<Point3<f64>> {
    let (v, t) = casing.hull().to_trimesh();
    let mut out = Vec::new();
    for [a, b, c] in t.iter().map(|f| f.map(|i| v[i as usize])) {
        let n = (((b - a).norm().max((c - a).norm()).max((c - b).norm())) / step).ceil() as usize;
        let n = n.max(1);
        for i in 0..=n {
            for j in 0..=n - i {
                let (u, w) = (i as f64 / n as f64, j as f64 / n as f64);
                out.push(a + (b - a) * u + (c - a) * w);
            }
        }
    }
    out
}

/// A coil facing the ellipsoid's surface point in direction `dir` (from its centre), `gap` m off
/// it, tilted `tilt` rad and spun `spin` rad.
fn facing(head: &HeadModel, dir: &Vector3<f64>, gap: f64, tilt: f64, spin: f64) -> Isometry3<f64> {
    let e = head.as_ellipsoid().unwrap();
    let centre = e.head_from_ellipsoid() * Point3::origin();
    let s = e.nearest(&(centre + dir.normalize() * 0.5));
    mocomp_testkit::anatomy::coil_facing(&s.point, &s.normal.into_inner(), gap, tilt, spin)
}

#[test]
fn the_casing_s_clearance_on_the_ellipsoid_is_the_hull_s_and_a_bound_above_the_cutoff() {
    let casing = d70();
    let coil = with_casing(&casing);
    let head = HeadModel::adult();
    let e = head.as_ellipsoid().unwrap();
    let dense = hull_points(&casing, 0.001);
    let mut rng = SplitMix64(52);
    let (mut clear, mut worst) = (0, 0.0f64);
    for _ in 0..120 {
        let dir = Vector3::new(
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.1,
        );
        let gap = -0.004 + 0.03 * rng.next_f64();
        let pose = facing(
            &head,
            &dir,
            gap,
            0.8 * (rng.next_f64() - 0.5),
            std::f64::consts::TAU * rng.next_f64(),
        );
        let d = coil.distance(&head, &pose);
        // The nearest of the dense points, each exactly: no nearer than the hull itself and
        // at most a sliver farther (the points are a millimetre apart on the hull's faces).
        let by_points = dense
            .iter()
            .map(|p| {
                let q = e.head_from_ellipsoid().inverse_transform_point(&(pose * p));
                ellipsoid_distance(&q.coords, e.radii())
            })
            .fold(f64::INFINITY, f64::min);
        if by_points > 0.0 {
            clear += 1;
            assert!(d <= by_points + 1e-9, "{d} {by_points}");
            worst = worst.max(by_points - d);
            assert!(by_points - d < 1e-4, "{d} {by_points}");
        } else {
            // Cutting in: never reported clear.
            assert!(d <= 1e-9, "{d} {by_points}");
        }
        for cutoff in [-0.01, 0.0, 0.003, 0.01, 0.05] {
            let below = coil.distance_below(&head, &pose, cutoff);
            if d < cutoff {
                assert_eq!(below, d);
            } else {
                assert!(
                    below >= cutoff && below <= d + 1e-12,
                    "{below} {d} {cutoff}"
                );
            }
        }
    }
    eprintln!(
        "{clear} clear poses: the hull's clearance within {:.2e} m of the dense points'",
        worst
    );
    assert!(clear > 60, "{clear}");
}

#[test]
fn a_goal_the_cylinder_clears_but_a_wing_of_the_casing_cuts_is_refused() {
    let casing = d70();
    let head = HeadModel::adult();
    let cylinder = CoilModel::cylinder(0.04, 0.03);
    let coil = with_casing(&casing);
    // Beside the head, 25 mm off, its wings (along the coil's x, 100 mm each way) along the
    // head's long axis, tilted further and further about the coil's y axis: a flat coil over a
    // convex head cuts in where its edge dips by more than the gap and the surface's fall
    // there (r·sin θ > gap + r²/2R), which the wing's tip at 100 mm reaches at a smaller tilt
    // than the cylinder's rim at 40 mm once the gap is this wide.
    let dir = Vector3::new(1.0, 0.0, 0.0);
    let min = 0.002;
    let tilted = (0..90)
        .map(|k| {
            let pose = facing(&head, &dir, 0.025, 0.0, std::f64::consts::FRAC_PI_2)
                * mocomp_geom::nalgebra::UnitQuaternion::from_axis_angle(
                    &Vector3::y_axis(),
                    k as f64 * 0.01,
                );
            (
                pose,
                cylinder.distance(&head, &pose),
                coil.distance(&head, &pose),
            )
        })
        .find(|(_, by_cylinder, by_casing)| *by_casing < 0.0 && *by_cylinder > 0.004);
    let (pose, by_cylinder, by_casing) = tilted.expect("no tilt where only the casing cuts in");
    eprintln!(
        "cylinder {:.1} mm clear, casing {:.1} mm",
        by_cylinder * 1e3,
        by_casing * 1e3
    );
    assert!(check_goal(&head, &cylinder, &pose, min).is_ok());
    match check_goal(&head, &coil, &pose, min) {
        Err(GoalError::InsideHead { distance_m, .. }) => assert_eq!(distance_m, by_casing),
        other => panic!("{other:?}"),
    }
}
