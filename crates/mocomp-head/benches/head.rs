//! What the head's queries cost: the ellipsoid against the fsaverage scalp (4 k triangles, from
//! MNE through the interop peer) and that scalp subdivided to 65 k and 260 k triangles (the
//! 100 k of a clinical scalp lies between), by the distance field and by parry's BVH, and what
//! building both costs; the coil's clearance sampled as the loop asks it (a new pose each call,
//! and remembering the last call while following the head), and exact as reports measure it.
//! The coil as SimNIBS's D70 casing against the cylinder (group `coil solid`).
//! `cargo bench -p mocomp-head` (needs the peers in .venv: `scripts/test.sh` installs them).
#![allow(
    missing_docs,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::print_stderr
)]

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_head::{CoilSolid, Ellipsoid, HeadShape, Mesh, MeshHead, repair};
use mocomp_testkit::{PythonPeer, SplitMix64};
use serde_json::json;
use std::hint::black_box;

fn fsaverage() -> Mesh {
    let mut peer = PythonPeer::start(
        "head_peer.py",
        "mne, nibabel, trimesh",
        "mne 1.13.2, nibabel 5.4.2, trimesh 5.2.0",
    );
    let a = peer.request(&json!({"op": "fsaverage_head"}));
    let num = |v: &serde_json::Value| v.as_f64().unwrap();
    let vertices = a["vertices_m"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| Point3::new(num(&p[0]), num(&p[1]), num(&p[2])))
        .collect();
    let triangles = a["triangles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| [0, 1, 2].map(|k| t[k].as_u64().unwrap() as u32))
        .collect();
    repair(
        Mesh {
            vertices,
            triangles,
        },
        "fsaverage",
    )
    .unwrap()
    .0
}

/// Points within ±30 mm of the surface (where the loop asks), and coil poses there facing it.
fn queries(head: &MeshHead, n: usize) -> (Vec<Point3<f64>>, Vec<Isometry3<f64>>) {
    let mut rng = SplitMix64(7);
    let v = head.vertices();
    let mut points = Vec::with_capacity(n);
    let mut poses = Vec::with_capacity(n);
    for _ in 0..n {
        let p = v[(rng.next_u64() % v.len() as u64) as usize];
        let s = head.nearest(&Point3::from(p.coords * 1.05));
        let off = (rng.next_f64() - 0.5) * 0.06;
        points.push(s.point + s.normal.into_inner() * off);
        // The coil's face 5–25 mm out, its +z into the head.
        let out = 0.005 + rng.next_f64() * 0.02;
        let face = s.point + s.normal.into_inner() * out;
        let rot = mocomp_geom::nalgebra::UnitQuaternion::rotation_between(
            &Vector3::z(),
            &-s.normal.into_inner(),
        )
        .unwrap_or_default();
        poses.push(Isometry3::from_parts(face.coords.into(), rot));
    }
    (points, poses)
}

fn bench(c: &mut Criterion) {
    let base = fsaverage();
    let coil = CoilSolid::new(0.04, 0.03).unwrap();
    let ellipsoid = Ellipsoid::new(
        Isometry3::translation(0.0, -0.01, -0.03),
        Vector3::new(0.085, 0.11, 0.13),
    )
    .unwrap();
    let meshes = [
        ("fsaverage 4k", base.clone()),
        ("fsaverage x4 65k", base.subdivided().subdivided()),
        (
            "fsaverage x4^3 260k",
            base.subdivided().subdivided().subdivided(),
        ),
    ];
    let mut g = c.benchmark_group("head query");
    let probe = MeshHead::new(base.clone(), "fsaverage").unwrap();
    let (points, poses) = queries(&probe, 256);
    // A coil that follows the head: within 0.2 mm and 0.2° of its goal (the first pose), a
    // different offset each call, as the loop's tracking error wanders.
    let following: Vec<Isometry3<f64>> = (0..256)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 256.0;
            let wobble = Isometry3::new(
                Vector3::new(a.cos(), a.sin(), (3.0 * a).sin()) * 0.0002,
                Vector3::new(a.sin(), a.cos(), 0.0) * 0.2f64.to_radians(),
            );
            poses[0] * wobble
        })
        .collect();
    g.bench_function("ellipsoid signed distance", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % points.len();
            black_box(ellipsoid.signed_distance(&points[i]))
        })
    });
    g.bench_function("ellipsoid coil clearance", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % poses.len();
            black_box(ellipsoid.coil_clearance(&poses[i], &coil))
        })
    });
    for (name, mesh) in &meshes {
        let head = MeshHead::new(mesh.clone(), name).unwrap();
        g.bench_with_input(
            BenchmarkId::new("mesh signed distance", name),
            &head,
            |b, h| {
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % points.len();
                    black_box(h.signed_distance(&points[i]))
                })
            },
        );
        g.bench_with_input(
            BenchmarkId::new("mesh signed distance by the BVH", name),
            &head,
            |b, h| {
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % points.len();
                    black_box(h.exact(&points[i]))
                })
            },
        );
        g.bench_with_input(
            BenchmarkId::new("mesh coil clearance sampled (the loop's)", name),
            &head,
            |b, h| {
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % poses.len();
                    black_box(h.coil_clearance_sampled(&poses[i], &coil, f64::INFINITY))
                })
            },
        );
        g.bench_with_input(
            BenchmarkId::new(
                "mesh coil clearance sampled, remembering (a coil following the head)",
                name,
            ),
            &head,
            |b, h| {
                let mut memory = mocomp_head::sampled::ClearanceMemory::new();
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % following.len();
                    black_box(h.coil_clearance_remembering(
                        &mut memory,
                        &following[i],
                        &coil,
                        f64::INFINITY,
                    ))
                })
            },
        );
        // The exact clearance two ways: parry's own query, and the one the crate answers with.
        type Exact = fn(&MeshHead, &Isometry3<f64>, &CoilSolid) -> f64;
        let exact: [(&str, Exact); 2] = [
            ("parry's query", MeshHead::coil_clearance_by_parry),
            ("bounded in the coil's axes", |h, p, c| {
                h.coil_clearance(p, c)
            }),
        ];
        for (how, f) in exact {
            g.bench_with_input(
                BenchmarkId::new(format!("mesh coil clearance exact ({how})"), name),
                &head,
                |b, h| {
                    let mut i = 0;
                    b.iter(|| {
                        i = (i + 1) % poses.len();
                        black_box(f(h, &poses[i], &coil))
                    })
                },
            );
        }
        eprintln!(
            "{name}: {} triangles, about {:.1} MB",
            head.triangles().len(),
            head.memory_bytes() as f64 / 1e6
        );
    }
    g.finish();
    let mut g = c.benchmark_group("head build");
    g.sample_size(10);
    for (name, mesh) in &meshes {
        g.bench_with_input(BenchmarkId::new("repair and index", name), mesh, |b, m| {
            b.iter(|| {
                let (m, _) = repair(m.clone(), name).unwrap();
                black_box(MeshHead::new(m, name).unwrap())
            })
        });
    }
    g.finish();
}

/// The coil as SimNIBS's D70 casing against the 40 × 30 mm cylinder, the same queries on the
/// ellipsoid and fsaverage: what a casing costs the loop.
fn bench_casing(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../mocomp-efield/tests/data/coils/MagStim_D70.stl");
    let bytes = std::fs::read(&path).expect("the D70 casing");
    let read = mocomp_head::formats::read_surface(
        "MagStim_D70.stl",
        &bytes,
        Some(mocomp_geom::LengthUnit::Millimetre),
    )
    .unwrap();
    let casing = mocomp_head::casing::Casing::new(&read.mesh.vertices, "MagStim_D70.stl").unwrap();
    let coils = [
        ("cylinder", CoilSolid::new(0.04, 0.03).unwrap()),
        ("D70 casing", CoilSolid::casing(std::sync::Arc::new(casing))),
    ];
    let head = MeshHead::new(fsaverage(), "fsaverage").unwrap();
    let ellipsoid = Ellipsoid::new(
        Isometry3::translation(0.0, -0.01, -0.03),
        Vector3::new(0.085, 0.11, 0.13),
    )
    .unwrap();
    let (_, poses) = queries(&head, 256);
    let mut g = c.benchmark_group("coil solid");
    for (name, coil) in &coils {
        g.bench_with_input(
            BenchmarkId::new("ellipsoid clearance (GJK)", name),
            coil,
            |b, coil| {
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % poses.len();
                    black_box(ellipsoid.coil_clearance(&poses[i], coil))
                })
            },
        );
        g.bench_with_input(
            BenchmarkId::new("fsaverage clearance sampled", name),
            coil,
            |b, coil| {
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % poses.len();
                    black_box(head.coil_clearance_sampled(&poses[i], coil, f64::INFINITY))
                })
            },
        );
        g.bench_with_input(
            BenchmarkId::new("fsaverage clearance exact", name),
            coil,
            |b, coil| {
                let mut i = 0;
                b.iter(|| {
                    i = (i + 1) % poses.len();
                    black_box(head.coil_clearance(&poses[i], coil))
                })
            },
        );
    }
    g.finish();
}

criterion_group!(benches, bench, bench_casing);
criterion_main!(benches);
