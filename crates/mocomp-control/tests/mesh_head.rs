//! The safety filter and the goal check on a real, non-convex head: FreeSurfer's fsaverage scalp
//! (from MNE-Python through the interop peer, required). Beside the ears, the nose and the brow
//! the coil's distance along its axis need not grow steadily; the standoff the filter asks for
//! must still clear the scalp by the requirement.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_control::safety::{backed_off, standoff_for};
use mocomp_control::{CoilModel, HeadModel};
use mocomp_geom::nalgebra::Point3;
use mocomp_head::{Head, HeadShape, Mesh, MeshHead, repair};
use mocomp_testkit::SplitMix64;
use std::sync::Arc;

fn fsaverage() -> Arc<MeshHead> {
    let (v, t) = mocomp_testkit::anatomy::fsaverage_head();
    let raw = Mesh {
        vertices: v.iter().map(|p| Point3::from(*p)).collect(),
        triangles: t,
    };
    let (mesh, _) = repair(raw, "fsaverage").unwrap();
    Arc::new(MeshHead::new(mesh, "fsaverage").unwrap())
}

#[test]
fn the_standoff_clears_a_real_scalp_by_the_requirement() {
    let scalp = fsaverage();
    let head = HeadModel::new(Head::Mesh(Arc::clone(&scalp)));
    let coil = CoilModel::cylinder(0.04, 0.03);
    let v = scalp.vertices();
    let mut rng = SplitMix64(17);
    let (mut backed, mut bounded) = (0, 0);
    for _ in 0..400 {
        let p = v[(rng.next_u64() % v.len() as u64) as usize];
        let s = scalp.nearest(&p);
        let n = s.normal.into_inner();
        // Facing the scalp, tilted up to 35°, from 10 mm inside to 5 mm off.
        let tilt = 1.2 * (rng.next_f64() - 0.5);
        let gap = -0.01 + 0.015 * rng.next_f64();
        let pose = mocomp_testkit::anatomy::coil_facing(&s.point, &n, gap, tilt, 0.0);
        let required = 0.005 * rng.next_f64();
        let standoff = standoff_for(&head, &coil, &pose, required, 0.1);
        let d = coil.distance(&head, &backed_off(&pose, standoff));
        if standoff >= 0.1 {
            bounded += 1;
        } else {
            assert!(
                d >= required - 1e-9,
                "{pose}: {d} < {required} at {standoff}"
            );
            backed += usize::from(standoff > 0.0);
        }
    }
    eprintln!("backed off {backed} of 400 poses; {bounded} at the bound");
    assert!(backed > 150, "{backed}");
}
