#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! `mocomp pointer calibrate` against pyigtl 0.3.4 (an independent Python OpenIGTLink
//! implementation, required) as the server a tracker or PLUS would run, streaming a stylus
//! pivoted about a divot: the tip recovered from its TRANSFORM messages. Noise model (seeded):
//! the marker's position 0.25 mm per axis and its orientation 0.05° per axis, 1σ, the pointer
//! tilted up to 30° from upright every way and spun about its length.

mod common;
use common::session::Session;
use common::{assert_success, mocomp, pyigtl_streaming, rows4};
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use mocomp_testkit::{SplitMix64, TempDir};
use serde_json::{Value, json};

/// The tip in the marker's frame and the divot in the tracker's, mm.
const TIP_MM: [f64; 3] = [2.5, -4.0, 161.0];
const DIVOT_MM: [f64; 3] = [120.0, -60.0, 1050.0];

fn pivoting(rng: &mut SplitMix64, n: usize) -> Vec<[[f64; 4]; 4]> {
    let tip = Vector3::from(TIP_MM);
    let divot = Point3::from(DIVOT_MM);
    (0..n)
        .map(|_| {
            let tilt_axis = Vector3::new(rng.gauss(), rng.gauss(), 0.0).normalize();
            let tilt = rng.next_f64() * 30f64.to_radians();
            let spin = (rng.next_f64() * 2.0 - 1.0) * std::f64::consts::PI;
            let r = UnitQuaternion::from_scaled_axis(tilt_axis * tilt)
                * UnitQuaternion::from_scaled_axis(Vector3::z() * spin);
            let noisy_r = UnitQuaternion::from_scaled_axis(
                Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * 0.05f64.to_radians(),
            ) * r;
            let t =
                divot.coords - r * tip + Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * 0.25;
            let m = Isometry3::from_parts(Translation3::from(t), noisy_r).to_homogeneous();
            rows4(&m)
        })
        .collect()
}

/// `mocomp pointer calibrate` on `frames` streamed by a pyigtl server at 200 Hz, taking
/// `samples`, writing `pointer.toml` in `dir`; its output and the file's path.
fn calibrate(
    frames: Vec<Value>,
    dir: &TempDir,
    samples: &str,
    extra: &[&str],
) -> (std::process::Output, String) {
    let (_py, addr) = pyigtl_streaming(frames, 200.0);
    let file = dir.path("pointer.toml");
    let mut args = vec![
        "pointer",
        "calibrate",
        "--igtl",
        &addr,
        "--samples",
        samples,
        "--out",
        &file,
    ];
    args.extend_from_slice(extra);
    (mocomp(&args), file)
}

#[test]
fn a_stylus_pivoted_on_a_pyigtl_server_is_calibrated_to_its_tip() {
    let mut rng = SplitMix64(32);
    let frames: Vec<Value> = pivoting(&mut rng, 260)
        .into_iter()
        .map(|m| json!({"StylusToTracker": m, "HeadToTracker": [[1,0,0,0],[0,1,0,0],[0,0,1,900],[0,0,0,1]]}))
        .collect();
    let dir = TempDir::new("pointer-cli");
    let (out, file) = calibrate(frames, &dir, "200", &["--json"]);
    assert_success(&out);
    let got: Value = serde_json::from_slice(&out.stdout).unwrap();
    let tip: Vec<f64> = (0..3)
        .map(|i| got["tip_in_marker_mm"][i].as_f64().unwrap())
        .collect();
    let err = (Vector3::new(tip[0], tip[1], tip[2]) - Vector3::from(TIP_MM)).norm();
    eprintln!(
        "pyigtl stylus: tip error {err:.3} mm, reported RMS {:.3} mm, max {:.3} mm, {} kept, turned {:.0}°",
        got["rms_mm"], got["max_mm"], got["kept"], got["spread_deg"]
    );
    // The tip lies 161 mm out: the marker's 0.05° of orientation noise alone moves it 0.14 mm.
    assert!(err < 0.3, "tip {tip:?} is {err:.3} mm off");
    assert_eq!(got["device"], "StylusToTracker");
    assert_eq!(
        got["kept"].as_u64().unwrap() + got["rejected"].as_u64().unwrap(),
        200
    );
    let rms = got["rms_mm"].as_f64().unwrap();
    assert!((0.25..0.7).contains(&rms), "RMS {rms}");
    // The file reads back as written.
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(
        text.contains("[pointer]") && text.contains("tip_in_marker_mm"),
        "{text}"
    );
}

#[test]
fn a_pointer_barely_turned_is_refused_with_how_far_it_turned() {
    // Only spun about its own length: the tip along it is not fixed.
    let frames: Vec<Value> = (0..80)
        .map(|k| {
            let r = UnitQuaternion::from_scaled_axis(Vector3::z() * (k as f64 * 0.05));
            let t = Vector3::from(DIVOT_MM) - r * Vector3::from(TIP_MM);
            let m = Isometry3::from_parts(Translation3::from(t), r).to_homogeneous();
            json!({"StylusToTracker": rows4(&m)})
        })
        .collect();
    let dir = TempDir::new("pointer-cli-narrow");
    let (out, file) = calibrate(frames, &dir, "60", &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("turned through") && err.contains("15°"),
        "{err}"
    );
    assert!(!std::path::Path::new(&file).exists());
}

#[test]
fn the_pivot_calibration_waits_for_the_consoles_go_and_shows_its_outcome() {
    let mut rng = SplitMix64(33);
    let frames: Vec<Value> = pivoting(&mut rng, 150)
        .into_iter()
        .map(|m| json!({"StylusToTracker": m}))
        .collect();
    // 40 a second: the page has 2.5 s to show the count before the process ends.
    let (_py, addr) = pyigtl_streaming(frames, 40.0);
    let dir = TempDir::new("pointer-console");
    let file = dir.path("pointer.toml");
    let s = Session::spawn(&[
        "pointer",
        "calibrate",
        "--igtl",
        &addr,
        "--samples",
        "100",
        "--out",
        &file,
        "--dashboard",
        "127.0.0.1:0",
    ]);
    let waiting = s.wait_status("the pivot waiting for the go", |v| {
        v["navigation"]["state"] == "waiting"
    });
    assert_eq!(waiting["navigation"]["task"], "pivot", "{waiting}");
    // Without the token the go is refused; nothing was collected.
    let (code, _) = s.post("/api/navigate", &[], &json!({}));
    assert_eq!(code, 401);
    assert!(!std::path::Path::new(&file).exists());
    let (code, _) = s.post_auth("/api/navigate", &json!({}));
    assert_eq!(code, 200);
    let (code, _) = s.post_auth("/api/navigate", &json!({}));
    assert_eq!(code, 409, "a second go");
    // The page follows the count (the process ends with the outcome: the browser test of
    // `register --dashboard` reads the panel's last state).
    let counting = s.wait_status("the pivot collecting", |v| {
        v["navigation"]["state"] == "running" && v["navigation"]["samples"][1] == 100
    });
    assert!(
        counting["reason"]
            .as_str()
            .unwrap()
            .contains("pivot the tip"),
        "{counting}"
    );
    let (ok, printed) = s.finish();
    assert!(ok, "{printed}");
    assert!(printed.contains("tip at"), "{printed}");
    assert!(std::path::Path::new(&file).exists());
}
