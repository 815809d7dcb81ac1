//! The loop's coil query on a real head: FreeSurfer's fsaverage scalp (from MNE-Python through
//! the interop peer, required), coils facing it anywhere from touching to 30 mm off, tilted, over
//! the ears, the brow and the nose. The sampled clearance the loop uses never claims less room
//! than the exact (GJK) one by more than rounding, and never more than the scalp can bulge
//! between its samples.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_head::inspect::inspect;
use mocomp_head::{CoilSolid, HeadShape, MeshHead};
use mocomp_testkit::{SplitMix64, TempDir};

fn fsaverage() -> MeshHead {
    let dir = TempDir::new("head-coil");
    let path = dir.path("head.ply");
    mocomp_testkit::anatomy::write_fsaverage(&path, "ply");
    let bytes = std::fs::read(&path).unwrap();
    let (mesh, _) = inspect(&path, &bytes, Some(LengthUnit::Millimetre)).unwrap();
    MeshHead::new(mesh, &path).unwrap()
}

/// SimNIBS's Magstim D70 casing (its `.stl`, mm, the coil's frame), as the solid.
fn d70() -> CoilSolid {
    d70_read().1
}

/// The D70's casing as read (coil frame, metres), and as the solid.
fn d70_read() -> (mocomp_head::Mesh, CoilSolid) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../mocomp-efield/tests/data/coils/MagStim_D70.stl");
    let bytes = std::fs::read(&path).unwrap();
    let read =
        mocomp_head::formats::read_surface("MagStim_D70.stl", &bytes, Some(LengthUnit::Millimetre))
            .unwrap();
    let casing = mocomp_head::casing::Casing::new(&read.mesh.vertices, "MagStim_D70.stl").unwrap();
    (read.mesh, CoilSolid::casing(std::sync::Arc::new(casing)))
}

/// A coil facing the scalp near `p`, its face `gap` off the surface along the normal.
fn facing(head: &MeshHead, p: &Point3<f64>, gap: f64, tilt: f64, spin: f64) -> Isometry3<f64> {
    let s = head.nearest(p);
    mocomp_testkit::anatomy::coil_facing(&s.point, &s.normal.into_inner(), gap, tilt, spin)
}

/// A coil facing the scalp at a random vertex, its face from `gap_from` to `gap_from + span` m
/// off it, tilted up to ±17° and spun anywhere.
fn random_facing(
    head: &MeshHead,
    rng: &mut SplitMix64,
    gap_from: f64,
    span: f64,
) -> Isometry3<f64> {
    let v = head.vertices();
    let p = v[(rng.next_u64() % v.len() as u64) as usize];
    let gap = gap_from + span * rng.next_f64();
    let tilt = 0.6 * (rng.next_f64() - 0.5);
    facing(head, &p, gap, tilt, std::f64::consts::TAU * rng.next_f64())
}

#[test]
fn the_sampled_clearance_is_the_exact_one_within_what_the_scalp_bulges_between_samples() {
    let head = fsaverage();
    sampled_within_the_bulge(
        &head,
        &CoilSolid::new(0.04, 0.03).unwrap(),
        1500,
        (1000, 200),
    );
}

/// The same for SimNIBS's D70 casing: its hull sampled 3 mm apart along the face's rim, 8 mm on the face and 12 mm
/// elsewhere (at most 512 points).
#[test]
fn a_casing_s_sampled_clearance_is_the_exact_one_within_what_the_scalp_bulges_between_samples() {
    let head = fsaverage();
    sampled_within_the_bulge(&head, &d70(), 1500, (400, 100));
}

/// Over `poses` random poses facing the scalp: the sampled clearance is never below the exact
/// one (beyond rounding) nor above it by more than the scalp may bulge between the coil's
/// samples (`between_samples_m`); at least `least.0`
/// poses clear of the scalp, `least.1` of them within 10 mm.
fn sampled_within_the_bulge(
    head: &MeshHead,
    coil: &CoilSolid,
    poses: usize,
    least: (usize, usize),
) {
    let mut rng = SplitMix64(41);
    let (mut worst_over, mut worst_under, mut sum, mut n, mut near) = (0.0f64, 0.0f64, 0.0, 0, 0);
    for _ in 0..poses {
        let pose = random_facing(head, &mut rng, -0.003, 0.033);
        let exact = head.coil_clearance(&pose, coil);
        let sampled = head.coil_clearance_sampled(&pose, coil, f64::INFINITY);
        if exact <= 0.0 {
            // Cutting in: both say so.
            assert!(sampled <= 0.002, "{pose}: sampled {sampled}, exact {exact}");
            continue;
        }
        near += usize::from(exact < 0.01);
        worst_over = worst_over.max(sampled - exact);
        // Beyond what the field ranks, a bound (the next test).
        if exact < mocomp_head::sampled::EXACT_BELOW_M - 0.0015 {
            worst_under = worst_under.max(exact - sampled);
        }
        sum += (sampled - exact).powi(2);
        n += 1;
        // Below a cutoff it is the same number; above, some number at least the cutoff.
        let cut = head.coil_clearance_sampled(&pose, coil, 0.005);
        if sampled < 0.005 {
            assert_eq!(cut, sampled);
        } else {
            assert!(cut >= 0.005);
        }
    }
    eprintln!(
        "{:?}: sampled against exact over {n} clear poses ({near} within 10 mm): over by at most \
         {:.3} mm, under by at most {:.4} mm, RMS {:.3} mm",
        coil.key(),
        worst_over * 1e3,
        worst_under * 1e3,
        (sum / n as f64).sqrt() * 1e3
    );
    // Every sample is a point of the coil: never nearer than the coil is (to GJK's tolerance).
    assert!(worst_under < 1e-6, "{worst_under}");
    assert!(
        worst_over < mocomp_head::sampled::between_samples_m(coil),
        "{worst_over}"
    );
    assert!(n > least.0 && near > least.1, "{n} {near}");
}

/// The memory the loop keeps between cycles changes the work, never the answer: along a coil's
/// wandering path over the scalp (steps of up to 2 mm and 2°, now and then a jump across the
/// head, a smaller coil or another cutoff), and on a second head, the remembering query gives
/// the very value of the one that looks every sample up, and looks up far fewer.
#[test]
fn remembering_the_last_cycle_spares_samples_and_changes_no_clearance() {
    let head = fsaverage();
    // Another head (the same scalp, 1 cm lower): a memory of the first says nothing of it.
    let moved = {
        let mut m = mocomp_head::Mesh {
            vertices: head.vertices().to_vec(),
            triangles: head.triangles().to_vec(),
        };
        m.vertices.iter_mut().for_each(|p| p.z -= 0.01);
        MeshHead::new(m, "lower").unwrap()
    };
    let lipschitz = head.lipschitz();
    assert!(
        (1.0..1.8).contains(&lipschitz),
        "the interpolated field should change about √3 per metre: {lipschitz}"
    );
    let coils = [
        CoilSolid::new(0.04, 0.03).unwrap(),
        CoilSolid::new(0.025, 0.02).unwrap(),
    ];
    let v = head.vertices();
    let mut rng = SplitMix64(97);
    let mut memory = mocomp_head::sampled::ClearanceMemory::new();
    let mut anchor = v[0];
    let (mut gap, mut tilt, mut spin) = (0.004, 0.0, 0.0);
    let (mut calls, mut near) = (0u64, 0);
    for step in 0..4000 {
        if step % 500 == 0 {
            anchor = v[(rng.next_u64() % v.len() as u64) as usize];
        }
        let jitter = |rng: &mut SplitMix64, by: f64| by * (2.0 * rng.next_f64() - 1.0);
        anchor += mocomp_geom::nalgebra::Vector3::new(
            jitter(&mut rng, 0.0012),
            jitter(&mut rng, 0.0012),
            jitter(&mut rng, 0.0012),
        );
        gap = (gap + jitter(&mut rng, 0.0005)).clamp(-0.003, 0.03);
        tilt = (tilt + jitter(&mut rng, 0.02)).clamp(-0.3, 0.3);
        spin += jitter(&mut rng, 0.02);
        let coil = &coils[usize::from(step % 1000 >= 900)];
        let on = if step % 700 >= 650 { &moved } else { &head };
        let cutoff = [f64::INFINITY, 0.005, 0.012, -0.002][(step / 250) % 4];
        let pose = facing(on, &anchor, gap, tilt, spin);
        let fresh = on.coil_clearance_sampled(&pose, coil, cutoff);
        let remembered = on.coil_clearance_remembering(&mut memory, &pose, coil, cutoff);
        assert_eq!(
            remembered.to_bits(),
            fresh.to_bits(),
            "step {step}: remembered {remembered}, looked up afresh {fresh}"
        );
        calls += 1;
        near += usize::from(fresh < 0.01);
    }
    let per_call = memory.looked_up() as f64 / calls as f64;
    eprintln!(
        "remembering: {per_call:.1} of {} samples looked up a call over {calls} calls ({near} within 10 mm)",
        mocomp_head::sampled::CYLINDER_SAMPLES
    );
    assert!(near > 1000, "{near}");
    assert!(
        per_call < mocomp_head::sampled::CYLINDER_SAMPLES as f64 / 2.0,
        "{per_call}"
    );
}

/// What the memory leans on: the interpolated field (the band's value beyond its grid) never
/// changes faster than the bound the field states, for pairs of points near the scalp, far
/// from it, and either side of the grid's edge.
#[test]
fn the_interpolated_field_changes_no_faster_than_its_stated_bound() {
    let head = fsaverage();
    let lipschitz = head.lipschitz();
    let b = head.bounds();
    let mut rng = SplitMix64(5);
    let band = mocomp_head::field::EXACT_BAND_M;
    let value = |p: &Point3<f64>| head.field_value(p).unwrap_or(band);
    let mut steepest = 0.0f64;
    for _ in 0..200_000 {
        // Anywhere from inside the head to 60 mm beyond its box (the grid ends 40 mm beyond).
        let a = Point3::from(b.min.coords.zip_map(&b.max.coords, |lo, hi| {
            lo - 0.06 + (hi - lo + 0.12) * rng.next_f64()
        }));
        let d = 0.01 * rng.next_f64();
        let dir = mocomp_geom::nalgebra::Vector3::new(
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
        )
        .normalize();
        let q = a + dir * d;
        let rate = (value(&a) - value(&q)).abs() / d;
        steepest = steepest.max(rate);
    }
    eprintln!("steepest seen {steepest:.3}, bound {lipschitz:.3}");
    assert!(steepest <= lipschitz + 1e-6, "{steepest} > {lipschitz}");
    assert!(
        steepest > 0.9,
        "the test never saw the field change: {steepest}"
    );
}

/// A coil farther off than the field ranks its samples (its nodes held at the band): the
/// sampled clearance says "at least this far", never more than the coil's true clearance.
#[test]
fn a_far_coil_gets_a_lower_bound_never_more_room_than_it_has() {
    let head = fsaverage();
    let coil = CoilSolid::new(0.04, 0.03).unwrap();
    let mut rng = SplitMix64(13);
    let floor = mocomp_head::sampled::EXACT_BELOW_M;
    let mut far = 0;
    for _ in 0..300 {
        let pose = random_facing(&head, &mut rng, 0.02, 0.05);
        let exact = head.coil_clearance(&pose, &coil);
        let sampled = head.coil_clearance_sampled(&pose, &coil, f64::INFINITY);
        if exact <= 0.0 {
            // Tilted into the scalp elsewhere: the first test's case.
            continue;
        }
        // Over by no more than the scalp bulges between the samples, as near the head.
        let between = mocomp_head::sampled::BETWEEN_SAMPLES_M;
        assert!(
            sampled <= exact + between,
            "{pose}: sampled {sampled}, exact {exact}"
        );
        if exact < floor - between {
            // Still exact among the samples: under by rounding alone.
            assert!(exact - sampled < 1e-6, "{pose}: {sampled} against {exact}");
        } else {
            // A bound: at least the floor less the interpolation's own slack.
            assert!(
                sampled >= floor - 0.0025,
                "{pose}: {sampled} against {exact}"
            );
            far += usize::from(exact > floor + 0.005);
        }
    }
    assert!(far > 100, "{far}");
}

/// The exact clearance (GJK on the triangles that can be nearest) is parry's own
/// cylinder-against-mesh distance, to GJK's tolerance (10 nm), for coils from cutting in to 80 mm off,
/// tilted and spun anywhere over the scalp, and a large coil and a thin one.
#[test]
fn the_exact_clearance_is_parrys_distance_between_the_solids() {
    let head = fsaverage();
    let mut rng = SplitMix64(77);
    let coils = [
        CoilSolid::new(0.04, 0.03).unwrap(),
        CoilSolid::new(0.07, 0.015).unwrap(),
        CoilSolid::new(0.02, 0.05).unwrap(),
        d70(),
    ];
    let (mut compared, mut touching, mut worst) = (0, 0, 0.0f64);
    for k in 0..900 {
        let coil = &coils[k % coils.len()];
        let pose = random_facing(&head, &mut rng, -0.004, 0.084);
        let ours = head.coil_clearance(&pose, coil);
        let parrys = head.coil_clearance_by_parry(&pose, coil);
        if ours < 0.0 {
            // A sample inside: the depth, where parry says only "touching".
            assert_eq!(parrys, 0.0, "{pose}: ours {ours}");
            continue;
        }
        touching += usize::from(parrys == 0.0);
        worst = worst.max((ours - parrys).abs());
        // GJK stops within its own tolerance, so two triangles nearly as near may come out a
        // nanometre apart in either order: the least can differ by that much.
        assert!(
            (ours - parrys).abs() < 1e-8,
            "{pose}: ours {ours}, parry's {parrys}"
        );
        compared += 1;
    }
    eprintln!("{compared} poses compared ({touching} touching between samples): worst {worst:e} m");
    assert!(compared > 700, "{compared}");
}

/// SimNIBS's D70 casing as the solid: its hull holds every point of the casing, is barely
/// larger, and its samples lie on it; against the ellipsoid its clearance (GJK on the hull) is
/// never more than any sample's and within the scalp's bulge of the least.
#[test]
fn the_d70_casing_is_its_hull_and_its_clearance_is_the_hull_s() {
    use mocomp_head::{Ellipsoid, HeadShape};
    use parry3d_f64::query::PointQuery;
    let (mesh, coil) = d70_read();
    let casing = coil.as_casing().unwrap();
    // Every casing point inside the hull and every sample on it (to rounding: parry builds the
    // hull within nanometres).
    for v in &mesh.vertices {
        let d = casing.hull().distance_to_local_point(v, true);
        assert!(d < 1e-8, "{v}: {d}");
    }
    for p in casing.samples() {
        let d = casing.hull().distance_to_local_point(p, false);
        assert!(d < 1e-8, "{p}: {d}");
    }
    assert!(casing.samples().len() <= mocomp_head::casing::MAX_SAMPLES);
    let (z_min, z_max) = casing.z_span();
    assert!(
        (z_min + 0.019).abs() < 1e-6 && (z_max + 0.001).abs() < 1e-6,
        "{z_min} {z_max}"
    );
    let head = Ellipsoid::adult();
    let mut rng = SplitMix64(5);
    let mut compared = 0;
    for _ in 0..400 {
        // Over the ellipsoid's upper half, tilted up to ±17°, from touching to 30 mm.
        let (a, b) = (std::f64::consts::TAU * rng.next_f64(), 1.3 * rng.next_f64());
        let dir =
            mocomp_geom::nalgebra::Vector3::new(b.sin() * a.cos(), b.sin() * a.sin(), b.cos());
        let along = head.radius_along(&dir);
        let surface = head.centre() + dir * along;
        let s = head.nearest(&surface);
        let pose = mocomp_testkit::anatomy::coil_facing(
            &s.point,
            &s.normal.into_inner(),
            0.03 * rng.next_f64(),
            0.6 * (rng.next_f64() - 0.5),
            std::f64::consts::TAU * rng.next_f64(),
        );
        let exact = head.coil_clearance(&pose, &coil);
        let least = casing
            .samples()
            .iter()
            .map(|p| head.signed_distance(&(pose * p)))
            .fold(f64::INFINITY, f64::min);
        if exact <= 0.0 {
            assert!(least <= 0.002, "{pose}: {least}");
            continue;
        }
        assert!(
            exact <= least + 1e-7,
            "{pose}: exact {exact} above a sample's {least}"
        );
        assert!(
            least - exact < mocomp_head::sampled::CASING_BETWEEN_SAMPLES_M,
            "{pose}: {least} {exact}"
        );
        compared += 1;
    }
    assert!(compared > 200, "{compared}");
}
