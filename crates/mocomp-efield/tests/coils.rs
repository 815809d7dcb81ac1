//! SimNIBS's own coil models (`tests/data/coils/`, GPL-3, from the SimNIBS repository): read
//! as SimNIBS reads them, and the field they give on a spherical head against the figures the
//! dose work rests on (lifting, sliding, tilting and turning the coil over a target 15 mm under
//! the scalp).
#![allow(clippy::unwrap_used)] // test code

use mocomp_efield::{DipoleCoil, PlacedCoil, Sphere, parse_ccd};
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::PI;

fn coil(name: &str) -> DipoleCoil {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/coils")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap();
    parse_ccd(&path.display().to_string(), &text).unwrap()
}

#[test]
fn both_coil_files_read_as_simnibs_describes_them() {
    let d70 = coil("MagStim_D70.ccd");
    assert_eq!(d70.len(), 964);
    assert_eq!(d70.name.as_deref(), Some("D70"));
    assert!((d70.didt_max_a_per_s.unwrap() - 114.73e6).abs() < 1.0);
    let fig8 = coil("Magstim_70mm_Fig8.ccd");
    assert_eq!(fig8.len(), 2712);
    assert_eq!(fig8.didt_max_a_per_s, None);
    // The windings behind the face (+z into the head): D70 −18 … −3 mm, Fig8 −8.8 … −4.2 mm.
    for (c, lo, hi) in [(&d70, -0.0181, -0.0029), (&fig8, -0.0089, -0.0041)] {
        for p in &c.positions {
            assert!(p.z > lo && p.z < hi, "{p}");
        }
    }
}

/// Sphere of 85 mm at the origin; the coil over its top, its face touching, +z down.
const R: f64 = 0.085;

fn over_top() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.0, 0.0, R),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), PI),
    )
}

/// The field along `along` at the target, 15 mm under the scalp on the coil's axis, for
/// `pose`, at 1 A/µs.
fn dose(coil: &DipoleCoil, pose: &Isometry3<f64>, along: &Vector3<f64>) -> f64 {
    let mut placed = PlacedCoil::with_capacity(coil.len());
    let sphere = Sphere::new(Point3::origin(), R).unwrap();
    placed.place(coil, pose, &sphere).unwrap();
    placed
        .e_field(&Point3::new(0.0, 0.0, R - 0.015), 1e6)
        .unwrap()
        .dot(along)
}

/// `pose` turned by `angle` about `axis` through `pivot` (head frame).
fn about(
    pose: &Isometry3<f64>,
    axis: Vector3<f64>,
    angle: f64,
    pivot: Point3<f64>,
) -> Isometry3<f64> {
    let turn =
        UnitQuaternion::from_axis_angle(&mocomp_geom::nalgebra::Unit::new_normalize(axis), angle);
    Isometry3::translation(pivot.x, pivot.y, pivot.z)
        * Isometry3::from_parts(Translation3::identity(), turn)
        * Isometry3::translation(-pivot.x, -pivot.y, -pivot.z)
        * pose
}

fn assert_near(what: &str, got: f64, want: f64, within: f64) {
    assert!(
        (got - want).abs() <= within * want.abs(),
        "{what}: {:.3} % against {:.3} %",
        got * 100.0,
        want * 100.0
    );
}

#[test]
fn the_dose_changes_with_the_coil_s_pose_as_the_literature_says() {
    // Magstim's 70 mm figure-of-eight, target 15 mm deep on the coil's axis.
    let fig8 = coil("Magstim_70mm_Fig8.ccd");
    let home = over_top();
    let e0 = {
        let mut placed = PlacedCoil::default();
        placed
            .place(&fig8, &home, &Sphere::new(Point3::origin(), R).unwrap())
            .unwrap();
        placed
            .e_field(&Point3::new(0.0, 0.0, R - 0.015), 1e6)
            .unwrap()
    };
    let along = e0.normalize();
    let d0 = dose(&fig8, &home, &along);
    let change = |pose: Isometry3<f64>| dose(&fig8, &pose, &along) / d0 - 1.0;
    // A full-output pulse of a Magstim (≈ 115 A/µs) gives ~150–200 V/m there.
    assert!(
        d0 * 114.73 > 120.0 && d0 * 114.73 < 250.0,
        "{d0} V/m per A/µs"
    );
    // Lifting: −4.3 % a millimetre, −19 % at 5 mm.
    assert_near(
        "lift 1 mm",
        change(Isometry3::translation(0.0, 0.0, 0.001) * home),
        -0.043,
        0.1,
    );
    assert_near(
        "lift 5 mm",
        change(Isometry3::translation(0.0, 0.0, 0.005) * home),
        -0.19,
        0.1,
    );
    // Sliding along the scalp (the coil turned about the sphere's centre): 0.1 % at 1 mm, 1–2 %
    // at 5 mm (1.0 % along the wings, 2.2 % across them: the literature's "1–2 %" to within
    // 10 %).
    let origin = Point3::origin();
    for axis in [Vector3::x(), Vector3::y()] {
        let one = change(about(&home, axis, 0.001 / R, origin));
        assert!(
            one < 0.0 && one > -0.0011,
            "slide 1 mm about {axis:?}: {one}"
        );
        let five = change(about(&home, axis, 0.005 / R, origin));
        assert!(
            five < -0.009 && five > -0.0225,
            "slide 5 mm about {axis:?}: {five}"
        );
    }
    // Tilting 1° about an edge 45 mm off the centre (a 90 mm wide casing): −3.4 %.
    let edge = home * Point3::new(0.0, 0.045, 0.0);
    let tilted = [1.0, -1.0]
        .map(|s| about(&home, Vector3::x(), s * PI / 180.0, edge))
        .into_iter()
        .find(|p| p.translation.z > R)
        .unwrap();
    assert_near("tilt 1° about the edge", change(tilted), -0.034, 0.1);
    // Turning 10° about its axis: the field turns with it, −1.5 % along the intended direction.
    let turned = home * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 10f64.to_radians());
    assert_near("turn 10°", change(turned), -0.015, 0.1);
}
