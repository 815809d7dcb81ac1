//! Registration on a real head: FreeSurfer's fsaverage scalp with its fiducials (from MNE
//! through the interop peer, required), placed anywhere in the tracker's view, the touches and
//! swept points made directly (the whole procedure with a simulated operator is
//! mocomp-app's `registration_trials`). Noise (seeded): each touch 0.7 mm per axis along the skin
//! off the landmark and the image's landmark as much off it, pressed in up to 1 mm; each swept
//! point pressed in up to 1 mm with 0.25 mm of tracker noise per axis.
//! - More data cannot make it worse: a sweep of one ring at brow level (which leaves the tilt of
//!   the head free) with the image's landmarks 3–4 mm off the scalp registers no worse than the
//!   landmarks alone, and its error bound holds.
//! - Each refusal names what to redo: a landmark touched far in the air (its distances to the
//!   others), one a little off the skin, an image landmark misplaced along the scalp, a sweep that does not lie on the scalp (the marker slipped), an error bound
//!   over its limit (naming the region to sweep), an image landmark far off the scalp.
//! - Points in the air (approaching, lifting off) never enter the fit.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use mocomp_head::{HeadShape, Mesh, MeshHead, repair};
use mocomp_nav::regions::regions;
use mocomp_nav::registration::on_scalp;
use mocomp_nav::verdict::verdict;
use mocomp_nav::{Landmark, Limits, NavError, NoiseModel, Refusal, Scalp, Target, register};
use mocomp_testkit::SplitMix64;

fn fsaverage() -> MeshHead {
    let (v, t) = mocomp_testkit::anatomy::fsaverage_head();
    let raw = Mesh {
        vertices: v.iter().map(|p| Point3::from(*p)).collect(),
        triangles: t,
    };
    let (mesh, _) = repair(raw, "fsaverage").unwrap();
    MeshHead::new(mesh, "fsaverage").unwrap()
}

/// A rigid pose anywhere in the tracker's view: the head marker's frame from the image's.
fn placement(rng: &mut SplitMix64) -> Isometry3<f64> {
    let axis = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss());
    Isometry3::from_parts(
        Translation3::new(
            rng.gauss() * 0.2,
            rng.gauss() * 0.2,
            -1.0 + rng.gauss() * 0.2,
        ),
        UnitQuaternion::from_scaled_axis(axis.normalize() * rng.angle()),
    )
}

/// `p` moved along the skin by `sigma` per axis and pressed in by up to 1 mm (image frame).
fn on_skin(rng: &mut SplitMix64, head: &MeshHead, p: &Point3<f64>, sigma: f64) -> Point3<f64> {
    let s = head.nearest(p);
    let n = s.normal.into_inner();
    let g = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * sigma;
    let moved = head.nearest(&(s.point + (g - n * g.dot(&n))));
    moved.point - moved.normal.into_inner() * (1e-3 * rng.next_f64())
}

/// The image's landmarks, the anatomical ones 0.7 mm per axis off them along the skin, touched
/// 0.7 mm per axis off those (marker frame).
fn touches(
    rng: &mut SplitMix64,
    head: &MeshHead,
    image: &[Landmark],
    marker_from_image: &Isometry3<f64>,
) -> Vec<Landmark> {
    image
        .iter()
        .map(|l| {
            let anatomical = on_skin(rng, head, &l.point, 0.7e-3);
            let touched = on_skin(rng, head, &anatomical, 0.7e-3);
            Landmark::new(&l.name, marker_from_image * touched)
        })
        .collect()
}

/// Swept points (marker frame) along a ring of elevation `z` (image frame, m) or, for `None`,
/// all over the head above the ears, with 0.25 mm of tracker noise per axis.
fn sweep(
    rng: &mut SplitMix64,
    head: &MeshHead,
    marker_from_image: &Isometry3<f64>,
    ring_z: Option<f64>,
    n: usize,
) -> Vec<Point3<f64>> {
    let centre = Point3::new(0.0, -0.015, 0.02);
    (0..n)
        .map(|i| {
            let a = std::f64::consts::TAU * i as f64 / n as f64;
            let d = match ring_z {
                Some(z) => Vector3::new(a.cos(), a.sin(), z).normalize(),
                None => Vector3::new(rng.gauss(), rng.gauss(), rng.gauss().abs() + 0.3).normalize(),
            };
            let hit = head
                .ray_hit(
                    &(centre + d * 0.3),
                    &-mocomp_geom::nalgebra::Unit::new_normalize(d),
                    0.3,
                )
                .unwrap();
            let e = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * 0.25e-3;
            let pressed = hit.point - hit.normal.into_inner() * (1e-3 * rng.next_f64());
            marker_from_image * (pressed + e)
        })
        .collect()
}

fn image_landmarks() -> (Vec<Landmark>, Vec<Target>) {
    let (fiducials, eeg) = mocomp_testkit::anatomy::fsaverage_points("fsaverage_1020");
    let image = fiducials
        .iter()
        .map(|(n, p)| Landmark::new(n, *p))
        .collect();
    let targets = vec![
        Target {
            name: "F3".into(),
            point: eeg["F3"],
        },
        Target {
            name: "C3".into(),
            point: eeg["C3"],
        },
    ];
    (image, targets)
}

fn error_at(found: &Isometry3<f64>, marker_from_image: &Isometry3<f64>, p: &Point3<f64>) -> f64 {
    (found * (marker_from_image * p) - p).norm()
}

/// The worst case: the image's landmarks 3–4 mm off the scalp (placed by eye on slices)
/// and one ring swept at brow level. The old registration pulled 14 mm away from the touched
/// landmarks and missed F3 by 7.7 mm while it said 5.7. Over 30 seeded trials here the ring
/// leaves F3 no worse than the landmarks alone (p95 within 0.3 mm), the bound holds in at least
/// 28 of 30, and no landmark is pulled beyond its noise.
#[test]
fn a_ring_with_landmarks_off_the_scalp_is_no_worse_than_the_landmarks_and_its_bound_holds() {
    let head = fsaverage();
    let scalp = Scalp::whole(&head);
    let (image, targets) = image_landmarks();
    let noise = NoiseModel::default();
    let mut rng = SplitMix64(49);
    let (mut alone, mut ring, mut held, mut pulled) = (vec![], vec![], 0, 0.0f64);
    for _ in 0..30 {
        let marker_from_image = placement(&mut rng);
        let touched = touches(&mut rng, &head, &image, &marker_from_image);
        // Placed by eye, 3–4 mm out of (or into) the scalp.
        let off: Vec<Landmark> = image
            .iter()
            .map(|l| {
                let n = head.nearest(&l.point).normal.into_inner();
                let side = if rng.next_f64() < 0.5 { 1.0 } else { -1.0 };
                Landmark::new(
                    &l.name,
                    l.point + n * side * (0.003 + 0.001 * rng.next_f64()),
                )
            })
            .collect();
        let swept = sweep(&mut rng, &head, &marker_from_image, Some(0.05), 250);
        let a = register(&scalp, &off, &touched, &[], &noise).unwrap();
        let r = register(&scalp, &off, &touched, &swept, &noise).unwrap();
        let f3 = &targets[0].point;
        alone.push(error_at(&a.image_from_marker, &marker_from_image, f3));
        let e = error_at(&r.image_from_marker, &marker_from_image, f3);
        ring.push(e);
        held += usize::from(e <= r.error_bound_at(f3));
        pulled = pulled.max(r.landmarks.iter().map(|l| l.error_m).fold(0.0, f64::max));
    }
    let p95 = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[(v.len() * 95) / 100]
    };
    let (a95, r95) = (p95(&mut alone), p95(&mut ring));
    eprintln!(
        "F3 p95: landmarks alone {:.2} mm, with the ring {:.2} mm; bound held {held}/30; farthest \
         landmark {:.2} mm",
        a95 * 1e3,
        r95 * 1e3,
        pulled * 1e3
    );
    assert!(r95 <= a95 + 0.3e-3, "{r95} {a95}");
    assert!(held >= 28, "{held}");
    assert!(pulled < 5e-3, "{pulled}");
}

/// Each way a registration goes wrong is refused with what to redo.
#[test]
fn each_refusal_names_what_to_redo() {
    let head = fsaverage();
    let scalp = Scalp::whole(&head);
    let (image, targets) = image_landmarks();
    let noise = NoiseModel::default();
    let limits = Limits {
        max_fre_m: 4e-3,
        max_error_m: 3e-3,
    };
    let all = regions(&scalp, &on_scalp(&scalp, &image).unwrap());
    let mut rng = SplitMix64(7);
    let marker_from_image = placement(&mut rng);
    let touched = touches(&mut rng, &head, &image, &marker_from_image);
    let swept = sweep(&mut rng, &head, &marker_from_image, None, 200);
    let judge = |image: &[Landmark], touched: &[Landmark], swept: &[Point3<f64>]| {
        let r = register(&scalp, image, touched, swept, &noise).unwrap();
        let on: Vec<_> = swept
            .iter()
            .map(|p| {
                let s = head.nearest(&(r.image_from_marker * p));
                (s.point, s.normal.into_inner())
            })
            .collect();
        (verdict(&r, &targets, &limits, &all, &on), r)
    };
    // All well: nothing refused, and the bound holds at F3.
    let (refused, r) = judge(&image, &touched, &swept);
    assert!(refused.is_empty(), "{refused:?}");
    let f3 = &targets[0].point;
    assert!(error_at(&r.image_from_marker, &marker_from_image, f3) <= r.error_bound_at(f3));
    // The lpa taken 45 mm out in the air.
    let at = |name: &str| image.iter().position(|l| l.name == name).unwrap();
    let lpa = at("lpa");
    let mut air = touched.clone();
    let out = (marker_from_image.rotation * head.nearest(&image[lpa].point).normal).into_inner();
    air[lpa].point += out * 0.045;
    let (refused, _) = judge(&image, &air, &swept);
    assert!(
        matches!(&refused[..], [Refusal::LandmarkMisplaced { name, .. }] if name == "lpa"),
        "{refused:?}"
    );
    assert!(
        refused[0].to_string().contains("touch the lpa again"),
        "{}",
        refused[0]
    );
    // The lpa touched 6 mm into the air: its distance to the rpa, or its distance from the
    // skin, gives it away.
    let mut hover = touched.clone();
    hover[lpa].point += out * 0.006;
    let (refused, _) = judge(&image, &hover, &swept);
    assert!(
        refused.iter().any(|f| matches!(f,
            Refusal::TouchedOffSkin { name, .. } | Refusal::LandmarkMisplaced { name, .. }
            if name == "lpa")),
        "{refused:?}"
    );
    // The image's rpa placed 9 mm off along the scalp.
    let mut wrong = image.clone();
    let k = at("rpa");
    let rpa = head.nearest(&wrong[k].point);
    let along = rpa.normal.into_inner().cross(&Vector3::z()).normalize();
    wrong[k].point = head.nearest(&(rpa.point + along * 0.009)).point;
    let (refused, _) = judge(&wrong, &touched, &swept);
    assert!(
        refused.iter().any(|f| matches!(f,
            Refusal::LandmarkDisagrees { name, .. } | Refusal::LandmarkMisplaced { name, .. }
            if name == "rpa")),
        "{refused:?}"
    );
    // The marker slipped 4 mm halfway through the sweep.
    let slip = Isometry3::translation(0.0, 0.004, 0.0);
    let slipped: Vec<Point3<f64>> = swept
        .iter()
        .enumerate()
        .map(|(k, p)| if k >= 100 { slip * p } else { *p })
        .collect();
    let (refused, _) = judge(&image, &touched, &slipped);
    assert!(
        refused
            .iter()
            .any(|f| matches!(f, Refusal::SweepHalvesDisagree { apart_m, .. }
            if *apart_m > 2e-3)),
        "{refused:?}"
    );
    // Landmarks alone: the bound at F3 over 3 mm, with the region to sweep named.
    let (refused, _) = judge(&image, &touched, &[]);
    match refused
        .iter()
        .find(|f| matches!(f, Refusal::TargetOverLimit { .. }))
    {
        Some(Refusal::TargetOverLimit {
            region: Some(r), ..
        }) => assert!(!r.is_empty()),
        other => panic!("{other:?} in {refused:?}"),
    }
    // An image landmark 15 mm out of the scalp: not a scalp landmark at all.
    let mut far = image.clone();
    let nasion = at("nasion");
    let out = head.nearest(&far[nasion].point).normal.into_inner();
    far[nasion].point += out * 0.015;
    let e = register(&scalp, &far, &touched, &swept, &noise).unwrap_err();
    assert!(
        matches!(e, NavError::LandmarkOffScalp { ref name, .. } if name == "nasion"),
        "{e}"
    );
}

/// Points approaching and lifting off the skin, 5–40 mm out, mixed into a sweep: none enters
/// the fit, which comes out as without them.
#[test]
fn points_in_the_air_never_enter_the_fit() {
    let head = fsaverage();
    let scalp = Scalp::whole(&head);
    let (image, _) = image_landmarks();
    let noise = NoiseModel::default();
    let mut rng = SplitMix64(11);
    let marker_from_image = placement(&mut rng);
    let touched = touches(&mut rng, &head, &image, &marker_from_image);
    let swept = sweep(&mut rng, &head, &marker_from_image, None, 150);
    let clean = register(&scalp, &image, &touched, &swept, &noise).unwrap();
    let image_from_marker = marker_from_image.inverse();
    let mut mixed = swept.clone();
    for p in swept.iter().step_by(3) {
        let q = image_from_marker * p;
        let n = head.nearest(&q).normal.into_inner();
        mixed.push(marker_from_image * (q + n * (0.005 + 0.035 * rng.next_f64())));
    }
    let r = register(&scalp, &image, &touched, &mixed, &noise).unwrap();
    let s = r.surface.unwrap();
    assert_eq!(s.off_skin, mixed.len() - swept.len(), "{s:?}");
    let moved = (r.image_from_marker.translation.vector
        - clean.image_from_marker.translation.vector)
        .norm();
    assert!(moved < 1e-9, "{moved}");
}
