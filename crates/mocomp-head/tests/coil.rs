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

/// A coil facing the scalp near `p`, its face `gap` off the surface along the normal.
fn facing(head: &MeshHead, p: &Point3<f64>, gap: f64, tilt: f64, spin: f64) -> Isometry3<f64> {
    let s = head.nearest(p);
    mocomp_testkit::anatomy::coil_facing(&s.point, &s.normal.into_inner(), gap, tilt, spin)
}

#[test]
fn the_sampled_clearance_is_the_exact_one_within_what_the_scalp_bulges_between_samples() {
    let head = fsaverage();
    let coil = CoilSolid::new(0.04, 0.03).unwrap();
    let v = head.vertices();
    let mut rng = SplitMix64(41);
    let (mut worst_over, mut worst_under, mut sum, mut n, mut near) = (0.0f64, 0.0f64, 0.0, 0, 0);
    for _ in 0..1500 {
        let p = v[(rng.next_u64() % v.len() as u64) as usize];
        let gap = -0.003 + 0.033 * rng.next_f64();
        let tilt = 0.6 * (rng.next_f64() - 0.5);
        let pose = facing(&head, &p, gap, tilt, std::f64::consts::TAU * rng.next_f64());
        let exact = head.coil_clearance(&pose, &coil);
        let sampled = head.coil_clearance_sampled(&pose, &coil, f64::INFINITY);
        if exact <= 0.0 {
            // Cutting in: both say so.
            assert!(sampled <= 0.002, "{pose}: sampled {sampled}, exact {exact}");
            continue;
        }
        near += usize::from(exact < 0.01);
        worst_over = worst_over.max(sampled - exact);
        worst_under = worst_under.max(exact - sampled);
        sum += (sampled - exact).powi(2);
        n += 1;
        // Below a cutoff it is the same number; above, some number at least the cutoff.
        let cut = head.coil_clearance_sampled(&pose, &coil, 0.005);
        if sampled < 0.005 {
            assert_eq!(cut, sampled);
        } else {
            assert!(cut >= 0.005);
        }
    }
    eprintln!(
        "sampled against exact over {n} clear poses ({near} within 10 mm): over by at most \
         {:.3} mm, under by at most {:.4} mm, RMS {:.3} mm",
        worst_over * 1e3,
        worst_under * 1e3,
        (sum / n as f64).sqrt() * 1e3
    );
    // Every sample is a point of the coil: never nearer than the coil is (to GJK's tolerance).
    assert!(worst_under < 1e-6, "{worst_under}");
    assert!(worst_over < 0.0015, "{worst_over}");
    assert!(n > 1000 && near > 200, "{n} {near}");
}
