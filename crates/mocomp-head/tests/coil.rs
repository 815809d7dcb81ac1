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
use mocomp_geom::nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use mocomp_head::inspect::inspect;
use mocomp_head::{CoilSolid, HeadShape, MeshHead};
use mocomp_testkit::{PythonPeer, SplitMix64, TempDir};
use serde_json::json;

fn fsaverage() -> MeshHead {
    let mut peer = PythonPeer::start(
        "head_peer.py",
        "mne, nibabel, trimesh",
        "mne 1.13.2, nibabel 5.4.2, trimesh 5.2.0",
    );
    let dir = TempDir::new("head-coil");
    let path = dir.path("head.ply");
    let a = peer.request(&json!({"op": "write", "format": "ply", "path": path, "scale": 1000.0}));
    assert!(a.get("error").is_none(), "{a}");
    let bytes = std::fs::read(&path).unwrap();
    let (mesh, _) = inspect(&path, &bytes, Some(LengthUnit::Millimetre)).unwrap();
    MeshHead::new(mesh, &path).unwrap()
}

/// A coil facing the scalp at vertex-near point `p`: its axis along the inward normal tilted by
/// up to `tilt`, its face `gap` off the surface along the normal.
fn facing(head: &MeshHead, p: &Point3<f64>, gap: f64, tilt: f64, spin: f64) -> Isometry3<f64> {
    let s = head.nearest(p);
    let n = s.normal.into_inner();
    let z = -n;
    let x = z
        .cross(&Vector3::x())
        .try_normalize(1e-6)
        .unwrap_or(Vector3::y());
    let y = z.cross(&x);
    let r = Rotation3::from_basis_unchecked(&[x, y, z]);
    let r = UnitQuaternion::from_rotation_matrix(&r)
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spin)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt);
    Isometry3::from_parts(Translation3::from(s.point.coords + n * gap), r)
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
