//! Interop: our lens model against OpenCV's 8-coefficient (rational) model, the one the Azure
//! Kinect SDK's factory calibration uses: projection against `projectPoints` and undistortion
//! against `undistortPointsIter`, for the Azure Kinect's calibration (NFOV unbinned, as the SDK
//! reports it for the recording in `../shared/data/azure-kinect/`), the Kinect v2's and seeded
//! coefficient sets near each (the same lens families), over the whole image.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_geom::nalgebra::Vector3;
use mocomp_testkit::{PythonPeer, SplitMix64};
use mocomp_vision::Intrinsics;
use mocomp_vision::intrinsics::PixelCentre;
use serde_json::json;

/// The Azure Kinect DK of the shared recording, NFOV unbinned (640×576), as `pyk4a` reports it.
fn azure_kinect() -> Intrinsics {
    Intrinsics {
        width: 640,
        height: 576,
        fx: 504.607_635_5,
        fy: 504.732_513_43,
        cx: 332.781_066_89,
        cy: 348.829_711_91,
        k1: 0.547_939_777,
        k2: -0.020_971_370_9,
        k3: -0.002_652_231_60,
        k4: 0.889_679_074,
        k5: 0.086_130_209_3,
        k6: -0.013_910_384_8,
        p1: 2.055_753_43e-5,
        p2: -7.210_415_79e-5,
        pixel_centre: PixelCentre::Integer,
    }
}

/// Whether the lens maps some ray onto every pixel: the distorted radius grows with the radius
/// until it passes the farthest corner's. (A rational model's coefficients are tied together:
/// changed one by one they can make a lens whose distorted radius turns back before the image's
/// corners, and a pixel there is no ray's image.)
fn maps_onto_image(k: &Intrinsics) -> bool {
    let corner = [(0.0, 0.0), (f64::from(k.width), f64::from(k.height))]
        .iter()
        .flat_map(|&(u, v)| [(u, 0.0), (0.0, v), (u, v)])
        .map(|(u, v)| ((u - k.cx) / k.fx).hypot((v - k.cy) / k.fy))
        .fold(0.0, f64::max);
    let mut last = 0.0;
    for i in 1..=4000 {
        let r = f64::from(i) * 1e-3;
        let (x, _) = k.distort(r, 0.0);
        if x <= last {
            return false;
        }
        if x > corner * 1.05 {
            return true;
        }
        last = x;
    }
    false
}

/// A lens near `base`: every coefficient and the focal lengths changed by up to ±20 %, the
/// principal point by up to ±10 px, drawn again until it maps onto the whole image.
fn near(base: &Intrinsics, rng: &mut SplitMix64) -> Intrinsics {
    loop {
        let k = perturbed(base, rng);
        if maps_onto_image(&k) {
            return k;
        }
    }
}

fn perturbed(base: &Intrinsics, rng: &mut SplitMix64) -> Intrinsics {
    let mut f = |x: f64| x * (0.8 + 0.4 * rng.next_f64());
    let mut k = Intrinsics {
        k1: f(base.k1),
        k2: f(base.k2),
        k3: f(base.k3),
        k4: f(base.k4),
        k5: f(base.k5),
        k6: f(base.k6),
        p1: f(base.p1),
        p2: f(base.p2),
        fx: f(base.fx),
        fy: f(base.fy),
        ..*base
    };
    k.cx += 20.0 * rng.next_f64() - 10.0;
    k.cy += 20.0 * rng.next_f64() - 10.0;
    k
}

fn check(peer: &mut PythonPeer, name: &str, k: &Intrinsics, rng: &mut SplitMix64) -> (f64, f64) {
    // Pixels over the whole image (corners and edges included), and points in front of the
    // camera that project into it.
    let mut pixels = vec![
        [0.0, 0.0],
        [f64::from(k.width - 1), 0.0],
        [0.0, f64::from(k.height - 1)],
        [f64::from(k.width - 1), f64::from(k.height - 1)],
    ];
    for _ in 0..200 {
        pixels.push([
            rng.next_f64() * f64::from(k.width - 1),
            rng.next_f64() * f64::from(k.height - 1),
        ]);
    }
    let cam = json!([k.fx, k.fy, k.cx, k.cy]);
    let d = json!(k.opencv_distortion());
    let v = peer.request(&json!({"op": "undistort", "k": cam, "d": d, "pixels": pixels}));
    let mut worst_undistort: f64 = 0.0;
    let mut points = Vec::new();
    for (p, n) in pixels.iter().zip(v["normalised"].as_array().unwrap()) {
        let ours = k.unproject(p[0], p[1], 1.0);
        // Ours is the preimage: it projects back onto the pixel.
        let (u, w) = k.project(&ours).unwrap();
        assert!(
            (u - p[0]).abs() < 1e-9 && (w - p[1]).abs() < 1e-9,
            "{name}: {p:?} undistorts to {ours} which projects to ({u}, {w})"
        );
        let cv = (n[0].as_f64().unwrap(), n[1].as_f64().unwrap());
        worst_undistort = worst_undistort.max((ours.x - cv.0).abs().max((ours.y - cv.1).abs()));
        points.push(ours * (0.4 + rng.next_f64()));
    }
    let pts: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
    let v = peer.request(&json!({"op": "project", "k": cam, "d": d, "points": pts}));
    let mut worst_project: f64 = 0.0;
    for (p, px) in points.iter().zip(v["pixels"].as_array().unwrap()) {
        let (u, w) = k.project(&Vector3::new(p.x, p.y, p.z)).unwrap();
        let cv = (px[0].as_f64().unwrap(), px[1].as_f64().unwrap());
        worst_project = worst_project.max((u - cv.0).abs().max((w - cv.1).abs()));
    }
    eprintln!("{name}: undistort {worst_undistort:.1e}, project {worst_project:.1e} px");
    (worst_undistort, worst_project)
}

#[test]
fn our_rational_lens_model_is_opencvs_in_both_directions() {
    let mut peer = PythonPeer::start("opencv_vision_peer.py", "opencv-python-headless", "4.14.0");
    let mut rng = SplitMix64(22);
    let mut kinect_v2 = Intrinsics::kinect_v2();
    // OpenCV's pixel centres are at integers: compare in that convention.
    kinect_v2.cx -= 0.5;
    kinect_v2.cy -= 0.5;
    kinect_v2.pixel_centre = PixelCentre::Integer;
    let azure = azure_kinect();
    let mut sets = vec![("azure kinect".to_string(), azure)];
    sets.push(("kinect v2".to_string(), kinect_v2));
    for i in 0..6 {
        sets.push((format!("near the azure kinect {i}"), near(&azure, &mut rng)));
        sets.push((
            format!("near the kinect v2 {i}"),
            near(&kinect_v2, &mut rng),
        ));
    }
    for (name, k) in &sets {
        let (undistort, project) = check(&mut peer, name, k, &mut rng);
        // Normalised coordinates (≈ 1/500 of a pixel per 1e-3): far below a pixel's millionth.
        assert!(undistort < 1e-9, "{name}: undistort differs by {undistort}");
        assert!(project < 1e-9, "{name}: projection differs by {project} px");
    }
}
