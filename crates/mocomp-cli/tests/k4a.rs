//! `mocomp track --recording`: rendered markers written as an Azure Kinect recording by the SDK's
//! own recorder (a real device's calibration attached: 640×576, rational lens), played back
//! through the SDK and tracked end to end: the same poses as from the same frames as PNGs, to
//! the bit, and within the PNG path's accuracy of the truth. A missing SDK, a missing or cut
//! recording are one clear line and exit 2.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

mod common;
use common::{assert_success, mocomp};

use mocomp_geom::nalgebra::Matrix4;
use mocomp_geom::{iso_from_matrix_mm, rotation_error, translation_error};
use mocomp_testkit::{TempDir, k4a_sdk_dir};
use serde_json::Value;

const GEOMETRY: &str =
    "name = \"8700449\"\npoints_mm = [[0,0,0],[0,47.38,28.99],[0,0,89.1],[0,-35.36,35.36]]\n";

fn calibration() -> String {
    format!(
        "{}/../mocomp-k4a/tests/data/azure-kinect/calibration.json",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn sdk() -> String {
    k4a_sdk_dir().display().to_string()
}

fn pose(v: &Value) -> mocomp_geom::nalgebra::Isometry3<f64> {
    let m = Matrix4::from_fn(|r, c| v[r][c].as_f64().unwrap());
    iso_from_matrix_mm(&m, 1e-6).unwrap()
}

fn lines(out: &std::process::Output) -> Vec<Value> {
    assert_success(out);
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn a_recording_of_rendered_markers_tracks_as_its_frames_do() {
    let d = TempDir::new("k4a-track");
    std::fs::write(d.path("g.toml"), GEOMETRY).unwrap();
    // The recording's directory is made, as --out's is.
    let (frames, mkv, sdk) = (d.path("frames"), d.path("recordings/markers.mkv"), sdk());
    let count = 30;
    let out = mocomp(&[
        "track",
        "render",
        "--out",
        &frames,
        "--geometry",
        &d.path("g.toml"),
        "--count",
        &count.to_string(),
        "--distractors",
        "--recording",
        &mkv,
        "--k4a-calibration",
        &calibration(),
        "--k4a-sdk",
        &sdk,
    ]);
    assert_success(&out);
    let from_png = lines(&mocomp(&[
        "track",
        "--frames",
        &frames,
        "--intrinsics",
        &d.path("frames/intrinsics.toml"),
        "--geometry",
        &d.path("g.toml"),
        "--json",
    ]));
    let from_mkv = lines(&mocomp(&[
        "track",
        "--recording",
        &mkv,
        "--geometry",
        &d.path("g.toml"),
        "--k4a-sdk",
        &sdk,
        "--overlay",
        &d.path("overlay"),
        "--json",
    ]));
    let truth: Vec<Value> = std::fs::read_to_string(d.path("frames/truth.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(from_mkv.len(), count);
    assert_eq!(from_png.len(), count);
    let (mut found, mut worst_mm, mut worst_deg) = (0, 0.0f64, 0.0f64);
    for (k, ((m, p), t)) in from_mkv.iter().zip(&from_png).zip(&truth).enumerate() {
        // Played back through the SDK, each capture is its frame: the same outcome to the bit.
        let mut m_same = m.clone();
        m_same.as_object_mut().unwrap().remove("device_usec");
        assert_eq!(&m_same, p, "capture {k}");
        // Its device timestamp, a period (30 frames a second) after the last.
        assert_eq!(
            m["device_usec"].as_u64().unwrap(),
            1_000_000 + k as u64 * 33_333
        );
        if m["found"] == true {
            found += 1;
            let (a, b) = (
                pose(&m["tracker_from_marker"]),
                pose(&t["tracker_from_marker"]),
            );
            worst_mm = worst_mm.max(translation_error(&a, &b) * 1e3);
            worst_deg = worst_deg.max(rotation_error(&a, &b).to_degrees());
        }
    }
    eprintln!(
        "640×576 recording: found {found} of {count}, worst {worst_mm:.2} mm, {worst_deg:.2}°"
    );
    // The PNG path's accuracy (tests/track.rs), on the Azure Kinect's lens.
    assert!(found >= count * 5 / 6, "found {found} of {count}");
    assert!(
        worst_mm < 3.0 && worst_deg < 2.0,
        "{worst_mm} mm, {worst_deg}°"
    );
    assert!(std::path::Path::new(&d.path("overlay/0000_overlay.png")).exists());
    // The text form says what the recording held.
    let out = track(&mkv, &d.path("g.toml"), &sdk);
    assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains(&format!(
            "found the marker in {found} of {count} frames (0 dropped"
        )),
        "{text}"
    );
}

/// Exit 2 and one line containing each of `needles`.
fn refused(out: &std::process::Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    // The SDK logs its own complaints on stderr (timestamped lines); ours is the last line.
    let ours: Vec<&str> = err.lines().filter(|l| !l.starts_with("[20")).collect();
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(ours.len(), 1, "{err}");
    for n in needles {
        assert!(ours[0].contains(n), "{:?} should name {n:?}", ours[0]);
    }
}

/// `mocomp track --recording path --geometry g --k4a-sdk sdk`.
fn track(path: &str, g: &str, sdk: &str) -> std::process::Output {
    mocomp(&[
        "track",
        "--recording",
        path,
        "--geometry",
        g,
        "--k4a-sdk",
        sdk,
    ])
}

/// The real device's recording in mocomp-k4a's test data.
fn real_recording() -> String {
    format!(
        "{}/../mocomp-k4a/tests/data/azure-kinect/recording.mkv",
        env!("CARGO_MANIFEST_DIR")
    )
}

#[test]
fn missing_sdks_and_bad_recordings_are_one_clear_line() {
    let d = TempDir::new("k4a-bad");
    std::fs::write(d.path("g.toml"), GEOMETRY).unwrap();
    let g = d.path("g.toml");
    let sdk = sdk();
    // No SDK where it is said to be: how to install it.
    let out = track(&d.path("x.mkv"), &g, &d.path("nowhere"));
    refused(&out, &["Azure Kinect SDK", "pyk4a-bundle"]);
    // A recording that is not there, or not one.
    refused(&track(&d.path("missing.mkv"), &g, &sdk), &["missing.mkv"]);
    std::fs::write(d.path("text.mkv"), "not a recording").unwrap();
    let out = track(&d.path("text.mkv"), &g, &sdk);
    refused(&out, &["text.mkv", "Azure Kinect recording"]);
    // One cut short.
    let whole = std::fs::read(real_recording()).unwrap();
    std::fs::write(d.path("cut.mkv"), &whole[..whole.len() / 2]).unwrap();
    refused(
        &track(&d.path("cut.mkv"), &g, &sdk),
        &["cut.mkv", "cut short"],
    );
    // A real device's recording without markers: tracked, found in none.
    let out = track(&real_recording(), &g, &sdk);
    assert_success(&out);
    assert!(
        String::from_utf8_lossy(&out.stdout).contains("found the marker in 0 of 1 frames"),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

/// Writes `seconds` of the example world's nodding head, as the Azure Kinect at the tracker's
/// place would have recorded it (the real device's calibration, 640×576, `fps` frames a second),
/// to `path`.
fn record_the_example_head(path: &str, seconds: f64, fps: u32) {
    use mocomp_vision::MarkerGeometry;
    use mocomp_vision::render::{RenderOptions, render};
    let text = common::example();
    let cfg = mocomp_app::config::Config::parse("run-sim.toml", &text).unwrap();
    let setup = mocomp_app::config::Setup::new(cfg, None, std::path::PathBuf::new()).unwrap();
    let s = &setup.file.tracker.simulated;
    let tracker_from_base = setup.base_from_tracker.inverse();
    let (rest, trajectory) = (s.base_from_head.iso(), s.motion.trajectory());
    let sdk = mocomp_k4a::Sdk::load(Some(&k4a_sdk_dir())).unwrap();
    let raw = std::fs::read(calibration()).unwrap();
    let intrinsics = sdk
        .intrinsics_from_raw(&raw, mocomp_k4a::DepthMode::NfovUnbinned)
        .unwrap();
    let mut r =
        mocomp_k4a::Recorder::create(&sdk, path, mocomp_k4a::DepthMode::NfovUnbinned, fps, &raw)
            .unwrap();
    let geometry = MarkerGeometry::ndi_8700449();
    let n = (seconds * f64::from(fps)) as u64;
    for k in 0..n {
        let t = k as f64 / f64::from(fps);
        let pose = tracker_from_base * rest * trajectory.rest_from_head(t);
        let options = RenderOptions {
            intrinsics,
            ..RenderOptions::kinect(pose, k)
        };
        let img = render(&geometry, &options);
        r.write(
            &img.ir,
            &img.depth,
            2_000_000 + k * 1_000_000 / u64::from(fps),
        )
        .unwrap();
    }
    r.finish().unwrap();
}

#[test]
fn the_loop_compensates_on_a_recorded_azure_kinect_and_holds_when_it_ends() {
    let d = TempDir::new("k4a-run");
    let mkv = d.path("head.mkv");
    // 9 s: room after the approach (about 4 s) for a retreat and a second approach (2 s),
    // which the safety filter takes when the camera's head estimate jumps towards the coil at the
    // goal, and still a few seconds of tracking.
    record_the_example_head(&mkv, 9.0, 30);
    let config = common::example_changed(
        &d,
        "127.0.0.86",
        &[(
            "source = \"simulated\"           # \"simulated\" or \"openigtlink\"",
            "source = \"k4a\"",
        )],
    );
    let mut text = std::fs::read_to_string(&config).unwrap();
    text.push_str(&format!(
        "\n[tracker.k4a]\nrecording = \"head.mkv\"\nsdk_dir = \"{}\"\nplayback = \"real_time\"\n",
        sdk()
    ));
    std::fs::write(&config, text).unwrap();
    // Not quiet: the notes (the camera's among them) go to stderr.
    let out = mocomp(&["run", "--config", &config, "--seconds", "10.5", "--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_success(&out);
    let r: Value = serde_json::from_slice(&out.stdout).unwrap();
    let c = &r["camera"];
    eprintln!(
        "camera: {c}\ntracking {} %, deviation rms {} mm\nevents: {}",
        r["tracking_percent"], r["deviation_rms_mm"], r["event_log"]
    );
    // Every capture tracked, the marker in nearly all, none dropped, then the recording's end.
    assert_eq!(c["frames"], 270, "{c}");
    assert!(c["found"].as_u64().unwrap() >= 255, "{c}");
    assert_eq!(c["dropped"], 0, "{c}");
    assert_eq!(c["ended"], "recording_ended", "{c}");
    assert!(
        stderr.contains("depth camera: the recording ended"),
        "{stderr}"
    );
    // Acquisition to pose: the pipeline's time and the hand-over (a fraction of a millisecond
    // here; the bound leaves room for a busy machine).
    let latency = c["latency_p99_ms"].as_f64().unwrap();
    assert!(latency > 0.0 && latency < 100.0, "{c}");
    // The loop followed the nodding head on the camera's poses (after its approach, about 4 s:
    // tracking about half of the run, a third after a retreat) ...
    assert!(r["tracking_percent"].as_f64().unwrap() > 20.0, "{r}");
    // (The simulated Kinect v2 camera, source "camera", gets 3.4 mm RMS on this world.)
    assert!(r["deviation_rms_mm"].as_f64().unwrap() < 5.0, "{r}");
    // ... and held when they stopped coming.
    let events = r["event_log"].to_string();
    assert!(
        events.contains("TrackerStale") || events.contains("stale"),
        "{events}"
    );
}
