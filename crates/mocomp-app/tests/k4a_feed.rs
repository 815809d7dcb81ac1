//! An Azure Kinect recording as the depth camera's feed (`tracker.source = "k4a"`), through the
//! SDK's own libraries (`.venv-k4a`): played in real time each frame comes when its timestamp
//! says, as fast as it goes they come at once; a gap in the timestamps is counted as dropped
//! frames; the last capture is followed by the recording's end.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_app::camera::FeedEvent;
use mocomp_app::camera::k4a::recording_feed;
use mocomp_app::camera_link::FeedEnd;
use mocomp_app::config::PlaybackPace;
use mocomp_k4a::{DepthMode, Recorder, Sdk};
use mocomp_testkit::{TempDir, k4a_sdk_dir};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

/// 10 captures at 30 frames a second, the fourth and fifth missing; returns the path.
fn recording(dir: &TempDir) -> String {
    let path = dir.path("gap.mkv");
    let sdk = Sdk::load(Some(&k4a_sdk_dir())).unwrap();
    let calibration = std::fs::read(format!(
        "{}/../mocomp-k4a/tests/data/azure-kinect/calibration.json",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    let mut r = Recorder::create(&sdk, &path, DepthMode::NfovUnbinned, 30, &calibration).unwrap();
    let blank = vec![0u16; 640 * 576];
    for k in (0..12u64).filter(|k| !matches!(k, 3 | 4)) {
        r.write(&blank, &blank, 5_000_000 + k * 33_333).unwrap();
    }
    r.finish().unwrap();
    path
}

/// Plays the whole feed: each frame's time since the start and drops, how long it took, and
/// how it ended.
fn play(path: &str, pace: PlaybackPace) -> (Vec<(f64, u64)>, f64, FeedEnd) {
    let sdk = Sdk::load(Some(&k4a_sdk_dir())).unwrap();
    let mut feed = recording_feed(&sdk, std::path::Path::new(path), pace).unwrap();
    assert_eq!(feed.intrinsics().width, 640);
    let stop = AtomicBool::new(false);
    let start = Instant::now();
    let mut frames = Vec::new();
    loop {
        match feed.next(&stop) {
            FeedEvent::Frame(f) => frames.push((f.t_s, f.dropped_before)),
            FeedEvent::End(why, _) => return (frames, start.elapsed().as_secs_f64(), why),
            other => panic!("{other:?}"),
        }
    }
}

#[test]
fn a_recording_plays_at_its_own_pace_or_at_once_and_names_its_gaps_and_end() {
    let dir = TempDir::new("k4a-feed");
    let path = recording(&dir);
    let (frames, took, end) = play(&path, PlaybackPace::RealTime);
    assert_eq!(end, FeedEnd::RecordingEnded);
    assert_eq!(frames.len(), 10);
    // Each frame at its timestamp's offset from the first; two missing before the fourth.
    for (k, (t, _)) in frames.iter().enumerate() {
        let n = if k >= 3 { k + 2 } else { k } as f64;
        assert!((t - n * 0.033_333).abs() < 1e-6, "frame {k}: {t}");
    }
    let drops: Vec<u64> = frames.iter().map(|f| f.1).collect();
    assert_eq!(drops, [0, 0, 0, 2, 0, 0, 0, 0, 0, 0]);
    // Real time: no sooner than the last timestamp (0.37 s after the first).
    assert!(took >= 0.36, "{took}");
    let (fast, _, end) = play(&path, PlaybackPace::Fast);
    assert_eq!(end, FeedEnd::RecordingEnded);
    assert_eq!(fast.len(), 10);
    assert_eq!(fast[3].1, 2);
    // As fast as it goes: stamped as read, not at the recording's offsets.
    assert!(fast[9].0 < frames[9].0, "{fast:?}");
}
