//! What the field costs: a point for SimNIBS's two coil models (964 and 2,712 dipoles) and
//! placing a coil at a new pose, as the loop asks each cycle. `cargo bench -p mocomp-efield`.
#![allow(missing_docs, clippy::unwrap_used)]

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use mocomp_efield::{DipoleCoil, PlacedCoil, Sphere, parse_ccd};
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use std::hint::black_box;

fn coil(name: &str) -> DipoleCoil {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/coils")
        .join(name);
    parse_ccd(name, &std::fs::read_to_string(path).unwrap()).unwrap()
}

fn bench(c: &mut Criterion) {
    let sphere = Sphere::new(Point3::origin(), 0.085).unwrap();
    let pose = |k: f64| {
        Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.087),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.01 * k)
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        )
    };
    let mut g = c.benchmark_group("efield");
    for name in ["MagStim_D70.ccd", "Magstim_70mm_Fig8.ccd"] {
        let coil = coil(name);
        let mut placed = PlacedCoil::with_capacity(coil.len());
        placed.place(&coil, &pose(0.0), &sphere).unwrap();
        let at = Point3::new(0.002, -0.003, 0.07);
        g.bench_with_input(BenchmarkId::new("point", coil.len()), &at, |b, at| {
            b.iter(|| placed.e_field(black_box(at), 1e8).unwrap())
        });
        let mut k = 0.0;
        g.bench_with_input(BenchmarkId::new("place", coil.len()), &coil, |b, coil| {
            b.iter(|| {
                k += 1.0;
                placed.place(coil, &pose(k), &sphere).unwrap()
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
