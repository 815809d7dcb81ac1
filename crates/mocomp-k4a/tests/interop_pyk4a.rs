//! The Azure Kinect SDK's own libraries (libk4a, libk4arecord 1.4.2 from the PyPI wheel
//! `pyk4a-bundle`, in `.venv-k4a`) driven by mocomp against `pyk4a`'s playback of the same
//! files: a recording from a real device (`tests/data/azure-kinect/`, MIT, see SOURCE.md) and
//! recordings mocomp writes with the SDK's recorder. Configuration, calibration, dimensions,
//! timestamps and every pixel (by two checksums) must agree. Also: a missing SDK, a missing
//! device and damaged files are named errors, never a crash.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_k4a::{DepthMode, Device, Image16, K4aError, Playback, Recorder, Sdk};
use mocomp_testkit::{PythonPeer, TempDir, k4a_sdk_dir};
use serde_json::{Value, json};
use std::sync::Arc;

fn data(name: &str) -> String {
    format!(
        "{}/tests/data/azure-kinect/{name}",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn sdk() -> Arc<Sdk> {
    Sdk::load(Some(&k4a_sdk_dir())).unwrap()
}

fn peer() -> PythonPeer {
    PythonPeer::start_k4a("pyk4a_peer.py", "pyk4a-bundle", "1.5.0")
}

/// The peer's two checksums of an image.
fn checksums(i: &Image16) -> (u64, u64) {
    let sum = i.data.iter().map(|&p| u64::from(p)).sum();
    let weighted = i.data.iter().zip(1u64..).fold(0u64, |a, (&p, k)| {
        a.wrapping_add(u64::from(p).wrapping_mul(k))
    });
    (sum, weighted)
}

/// Every capture of `path`, ours against pyk4a's.
fn same_captures(path: &str, theirs: &Value) -> usize {
    let mut p = Playback::open(&sdk(), path).unwrap();
    let mut n = 0;
    while let Some(c) = p.next_capture().unwrap() {
        let t = &theirs["captures"][n];
        for (ours, t, what) in [(&c.ir, &t["ir"], "ir"), (&c.depth, &t["depth"], "depth")] {
            let Some(i) = ours else {
                assert!(t.is_null(), "capture {n}: pyk4a has {what}, we do not");
                continue;
            };
            assert_eq!(
                (i64::from(i.height), i64::from(i.width)),
                (
                    t["shape"][0].as_i64().unwrap(),
                    t["shape"][1].as_i64().unwrap()
                ),
                "capture {n} {what}"
            );
            assert_eq!(
                i.device_usec,
                t["timestamp_usec"].as_u64().unwrap(),
                "capture {n} {what}"
            );
            let (sum, weighted) = checksums(i);
            assert_eq!(sum, t["sum"].as_u64().unwrap(), "capture {n} {what}");
            assert_eq!(
                weighted,
                t["weighted"].as_u64().unwrap(),
                "capture {n} {what}"
            );
        }
        n += 1;
    }
    assert_eq!(n, theirs["captures"].as_array().unwrap().len());
    n
}

#[test]
fn a_real_devices_recording_plays_as_pyk4a_plays_it() {
    let path = data("recording.mkv");
    let theirs = peer().request(&json!({"op": "read", "path": path}));
    let p = Playback::open(&sdk(), &path).unwrap();
    let info = p.info();
    let cfg = &theirs["configuration"];
    assert_eq!(info.depth_mode, Some(DepthMode::NfovUnbinned));
    assert_eq!(
        i64::from(info.depth_mode.unwrap().raw()),
        cfg["depth_mode"].as_i64().unwrap()
    );
    assert_eq!(info.fps, 5);
    assert_eq!(cfg["camera_fps"], 0, "the SDK's K4A_FRAMES_PER_SECOND_5");
    assert_eq!(info.ir_track, cfg["ir_track_enabled"].as_bool().unwrap());
    assert_eq!(
        info.depth_track,
        cfg["depth_track_enabled"].as_bool().unwrap()
    );
    assert_eq!(
        u64::from(info.start_offset_usec),
        cfg["start_timestamp_offset_usec"].as_u64().unwrap()
    );
    assert_eq!(info.length_usec, theirs["length_usec"].as_u64().unwrap());
    // The depth camera's calibration, as OpenCV's camera matrix and 8 coefficients.
    let k = p.intrinsics().unwrap();
    let m = &theirs["depth_camera"]["matrix"];
    let f = |v: &Value| v.as_f64().unwrap();
    assert_eq!((k.width, k.height), (640, 576));
    assert_eq!(
        [k.fx, k.fy, k.cx, k.cy],
        [f(&m[0][0]), f(&m[1][1]), f(&m[0][2]), f(&m[1][2])]
    );
    let d: Vec<f64> = theirs["depth_camera"]["distortion"]
        .as_array()
        .unwrap()
        .iter()
        .map(f)
        .collect();
    // (To the last bit but one: serde_json's decimal parsing is not correctly rounded.)
    for (a, b) in k.opencv_distortion().iter().zip(&d) {
        assert!((a - b).abs() <= 1e-15 * b.abs().max(1e-3), "{a} vs {b}");
    }
    assert_eq!(d.len(), 8);
    // Its one capture, pixel for pixel.
    assert_eq!(same_captures(&path, &theirs), 1);
    eprintln!("recording: {info:?}; {k:?}");
}

/// A 640×576 test pattern that differs per frame.
fn pattern(k: u64) -> (Vec<u16>, Vec<u16>) {
    let n = 640 * 576;
    let ir = (0..n)
        .map(|i| ((i as u64 * 7 + k * 131) % 4000) as u16)
        .collect();
    let depth = (0..n)
        .map(|i| (500 + (i as u64 + k * 17) % 3000) as u16)
        .collect();
    (ir, depth)
}

/// A recording at `path`, 640×576 at 30 frames a second, the real device's calibration attached.
fn recorder(path: &str) -> Recorder {
    let calibration = std::fs::read(data("calibration.json")).unwrap();
    Recorder::create(&sdk(), path, DepthMode::NfovUnbinned, 30, &calibration).unwrap()
}

#[test]
fn recordings_we_write_with_the_sdks_recorder_read_back_in_pyk4a_pixel_for_pixel() {
    let dir = TempDir::new("mocomp-k4a-record");
    let path = dir.path("pattern.mkv");
    let mut r = recorder(&path);
    let frames = 12u64;
    for k in 0..frames {
        let (ir, depth) = pattern(k);
        // A dropped frame after the fifth: its timestamp is two periods on.
        let t = 1_000_000 + k * 33_333 + if k > 5 { 33_333 } else { 0 };
        r.write(&ir, &depth, t).unwrap();
    }
    assert_eq!(r.finish().unwrap(), frames);
    let theirs = peer().request(&json!({"op": "read", "path": path}));
    assert_eq!(same_captures(&path, &theirs), frames as usize);
    // The calibration attached is the device's, per mode, as the real recording's.
    let calibration = std::fs::read(data("calibration.json")).unwrap();
    let ours = Playback::open(&sdk(), &path).unwrap();
    let real = Playback::open(&sdk(), &data("recording.mkv")).unwrap();
    assert_eq!(ours.intrinsics().unwrap(), real.intrinsics().unwrap());
    // And as the SDK computes them from the raw calibration for the mode.
    let from_raw = sdk()
        .intrinsics_from_raw(&calibration, DepthMode::NfovUnbinned)
        .unwrap();
    assert_eq!(from_raw, real.intrinsics().unwrap());
    let binned = sdk()
        .intrinsics_from_raw(&calibration, DepthMode::NfovBinned)
        .unwrap();
    assert_eq!((binned.width, binned.height), (320, 288));
    assert!((binned.fx * 2.0 - from_raw.fx).abs() < 1e-3, "{binned:?}");
    assert!(
        sdk()
            .intrinsics_from_raw(b"{}", DepthMode::NfovUnbinned)
            .is_err()
    );
    assert_eq!(ours.info().fps, 30);
    // Our pixels went in as they came out.
    let mut p = Playback::open(&sdk(), &path).unwrap();
    let c = p.next_capture().unwrap().unwrap();
    assert_eq!(c.ir.unwrap().data, pattern(0).0);
    assert_eq!(c.depth.unwrap().data, pattern(0).1);
}

#[test]
fn a_missing_sdk_says_how_to_install_it() {
    let dir = TempDir::new("mocomp-k4a-nosdk");
    for e in [
        Sdk::load(Some(std::path::Path::new(&dir.path("")))).unwrap_err(),
        Sdk::load(Some(std::path::Path::new("/nonexistent/k4a"))).unwrap_err(),
    ] {
        let text = e.to_string();
        assert!(matches!(e, K4aError::SdkMissing { .. }), "{text}");
        assert!(
            text.contains("pyk4a-bundle") && text.contains("libk4a1.4"),
            "{text}"
        );
    }
}

#[test]
fn without_a_camera_opening_one_is_a_named_error() {
    let e = Device::open(&sdk(), None).unwrap_err();
    assert!(matches!(e, K4aError::NoDevice(_)), "{e}");
    assert!(e.to_string().contains("no Azure Kinect"), "{e}");
    let e = Device::open(&sdk(), Some("000123456789")).unwrap_err();
    assert!(matches!(e, K4aError::NoDevice(_)), "{e}");
}

#[test]
fn truncated_and_damaged_recordings_are_named_errors_not_crashes() {
    let dir = TempDir::new("mocomp-k4a-damaged");
    let path = dir.path("whole.mkv");
    let mut r = recorder(&path);
    for k in 0..8 {
        let (ir, depth) = pattern(k);
        r.write(&ir, &depth, 1_000_000 + k * 33_333).unwrap();
    }
    r.finish().unwrap();
    let whole = std::fs::read(&path).unwrap();
    // Cut anywhere: the index at the end is gone, and the SDK will not open it.
    for percent in [1, 10, 50, 90, 99] {
        let cut = dir.path(&format!("cut{percent}.mkv"));
        std::fs::write(&cut, &whole[..whole.len() * percent / 100]).unwrap();
        let e = Playback::open(&sdk(), &cut).unwrap_err();
        assert!(matches!(e, K4aError::Recording { .. }), "{percent} %: {e}");
        assert!(e.to_string().contains(&cut), "{e}");
    }
    // Damaged inside (bytes overwritten, length kept): an error (at opening, or at the capture
    // that cannot be read, naming how far it got), or captures the SDK still decodes; never a
    // panic or a hang.
    for at in [20, 40, 60, 80] {
        let mut bad = whole.clone();
        let start = bad.len() * at / 100;
        for b in &mut bad[start..start + 4096] {
            *b = 0xA5;
        }
        let damaged = dir.path(&format!("damaged{at}.mkv"));
        std::fs::write(&damaged, &bad).unwrap();
        let outcome = Playback::open(&sdk(), &damaged).and_then(|mut p| {
            let mut n = 0;
            while p.next_capture()?.is_some() {
                n += 1;
            }
            Ok(n)
        });
        eprintln!("damaged at {at} %: {outcome:?}");
        if let Err(e) = outcome {
            assert!(e.to_string().contains(&damaged), "{e}");
        }
    }
    // Not a recording at all.
    let text = dir.path("notes.mkv");
    std::fs::write(&text, "not matroska").unwrap();
    assert!(Playback::open(&sdk(), &text).is_err());
    let missing = dir.path("missing.mkv");
    let e = Playback::open(&sdk(), &missing).unwrap_err();
    assert!(e.to_string().contains("missing.mkv"), "{e}");
}
