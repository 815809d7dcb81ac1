//! The compensation cycle's compute time: tracker rules, prediction, goal, IK on the current
//! branch, limits, collision check of the command. The robot here is in memory (it follows the
//! command exactly and reports a healthy state), so the figure is the cycle's own work, without
//! the socket write of the real client; `mocomp run` reports the live figure with it.
//!
//! Besides criterion's median, the bench times 20,000 consecutive cycles one by one on a nodding,
//! noisy head and prints their median, p99 and max (the goal: p99 under 20 µs), for each
//! head model in the same run: the ellipsoid, FreeSurfer's fsaverage scalp (4 k triangles, from
//! MNE through the interop peer, which `scripts/test.sh` installs) and that scalp split to
//! 110 k triangles (a clinical scalp's size); on the ellipsoid without the learned prediction
//! (`[predictor] learned = false`), for its cost; and on the ellipsoid with the dose each cycle
//! (SimNIBS's Magstim D70, 964 dipoles: the measured coil against its goal's plan, as
//! `mocomp run` does with `[coil] model`), for the dose's cost; and with SimNIBS's D70 casing
//! as the coil's solid (`[coil] casing`) on the ellipsoid and the fsaverage scalp, for the
//! casing's cost against the cylinder's.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // bench code

use criterion::{Criterion, criterion_group, criterion_main};
use mocomp_control::{HeadModel, Mode};
use mocomp_efield::{DoseModel, DosePlans, parse_ccd};
use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::Point3;
use mocomp_head::casing::Casing;
use mocomp_head::formats::read_casing;
use mocomp_head::{Head, Mesh, MeshHead, repair};
use std::sync::Arc;
use std::time::Instant;

#[path = "../tests/common/mem.rs"]
mod mem;
use mem::World;

/// The heads: the ellipsoid, the fsaverage scalp, and that scalp split to 110 k triangles.
fn heads() -> Vec<(String, HeadModel)> {
    let (v, t) = mocomp_testkit::anatomy::fsaverage_head();
    let raw = Mesh {
        vertices: v.iter().map(|p| Point3::from(*p)).collect(),
        triangles: t,
    };
    let (mesh, _) = repair(raw, "fsaverage").unwrap();
    let fine = mesh
        .split_at_centroids()
        .split_at_centroids()
        .split_at_centroids();
    let mut out = vec![("ellipsoid".to_string(), HeadModel::adult())];
    for m in [mesh, fine] {
        let name = format!("fsaverage {} k", m.triangles.len() / 1000);
        let t0 = Instant::now();
        let head = MeshHead::new(m, &name).unwrap();
        eprintln!(
            "{name}: built in {:.2} s, about {:.1} MB",
            t0.elapsed().as_secs_f64(),
            head.memory_bytes() as f64 / 1e6
        );
        out.push((name, HeadModel::new(Head::Mesh(Arc::new(head)))));
    }
    out
}

/// The goal's dose plan with SimNIBS's Magstim D70 at full output on `head`.
fn d70_plans(head: &HeadModel) -> DosePlans {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../mocomp-efield/tests/data/coils/MagStim_D70.ccd");
    let coil = parse_ccd("D70", &std::fs::read_to_string(path).unwrap()).unwrap();
    let model = DoseModel {
        didt_a_per_s: coil.didt_max_a_per_s.unwrap(),
        coil: Arc::new(coil),
        depth_m: 0.015,
    };
    let goal = mocomp_testkit::scene::head_from_coil_goal();
    DosePlans::new(&model, head.shape(), Some(&goal), &[]).unwrap()
}

/// One cycle, and its dose when `dose` is given (what `mocomp run`'s loop thread does).
fn cycle(w: &mut World, dose: Option<&mut DosePlans>) -> Mode {
    let rec = w.cycle_record();
    if let (Some(d), Some(coil)) = (dose, rec.coil_now) {
        std::hint::black_box(d.dose_at_goal(&rec.head_from_coil_goal, &coil));
    }
    rec.mode
}

/// SimNIBS's Magstim D70 casing (its `.stl`, mm, the coil's frame).
fn d70_casing() -> Arc<Casing> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../mocomp-efield/tests/data/coils/MagStim_D70.stl");
    let bytes = std::fs::read(path).unwrap();
    Arc::new(read_casing("MagStim_D70.stl", &bytes, LengthUnit::Millimetre).unwrap())
}

/// How a bench run's loop differs from the built-in world's.
struct Variant {
    learned: bool,
    casing: Option<Arc<Casing>>,
}

fn percentiles(name: &str, head: &HeadModel, v: &Variant, mut dose: Option<DosePlans>) {
    let mut w = World::with_config(head.clone(), |c| {
        c.predictor.learned = v.learned;
        c.coil.casing = v.casing.clone();
    });
    let mut ns: Vec<u64> = Vec::with_capacity(20_000);
    let mut tracking = 0;
    for _ in 0..20_000 {
        let t0 = Instant::now();
        let mode = std::hint::black_box(cycle(&mut w, dose.as_mut()));
        ns.push(t0.elapsed().as_nanos() as u64);
        tracking += usize::from(mode == Mode::Tracking);
    }
    ns.sort_unstable();
    let at = |p: f64| ns[((ns.len() - 1) as f64 * p) as usize] as f64 / 1e3;
    eprintln!(
        "cycle on the {name}, 20,000 consecutive (tracking {tracking}): median {:.2} µs, p99 {:.2} µs, max {:.2} µs",
        at(0.5),
        at(0.99),
        at(1.0)
    );
}

fn bench(c: &mut Criterion) {
    let heads = heads();
    let plain = Variant {
        learned: true,
        casing: None,
    };
    for (name, head) in &heads {
        percentiles(name, head, &plain, None);
    }
    // What the learned prediction, the dose and the casing cost, in the same run.
    let filter_alone = Variant {
        learned: false,
        casing: None,
    };
    percentiles(
        "ellipsoid, the filter alone (learned = false)",
        &heads[0].1,
        &filter_alone,
        None,
    );
    let plans = d70_plans(&heads[0].1);
    percentiles(
        "ellipsoid, with the dose (D70)",
        &heads[0].1,
        &plain,
        Some(plans.clone()),
    );
    let cased = Variant {
        learned: true,
        casing: Some(d70_casing()),
    };
    for (name, head) in &heads[..2] {
        percentiles(&format!("{name}, the D70's casing"), head, &cased, None);
    }
    for (name, head) in &heads {
        let mut w = World::with_head(head.clone());
        c.bench_function(&format!("cycle (tracking a nodding head), {name}"), |b| {
            b.iter(|| std::hint::black_box(w.cycle()))
        });
    }
    for (name, head) in &heads[..2] {
        let mut w = World::with_config(head.clone(), |c| c.coil.casing = cased.casing.clone());
        c.bench_function(
            &format!("cycle (tracking a nodding head), {name}, the D70's casing"),
            |b| b.iter(|| std::hint::black_box(w.cycle())),
        );
    }
    let mut w = World::with_head(heads[0].1.clone());
    let mut plans = plans;
    c.bench_function(
        "cycle (tracking a nodding head), ellipsoid, with the dose (D70)",
        |b| b.iter(|| std::hint::black_box(cycle(&mut w, Some(&mut plans)))),
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
