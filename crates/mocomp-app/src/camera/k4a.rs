//! An Azure Kinect as the depth camera (`tracker.source = "k4a"`, `[tracker.k4a]`): a device's
//! captures, or a recording's played in real time or as fast as it goes, as a [`Feed`] for
//! [`crate::camera::CameraServer`]. Each frame is stamped with its exposure on this host's clock:
//! a device's timestamps through [`mocomp_k4a::clock::DeviceClock`], a recording's relative to
//! its first capture from when playing began.

use crate::camera::{CameraServer, Feed, FeedEvent, FeedFrame};
use crate::camera_link::{FeedEnd, VisionLink};
use crate::config::{PlaybackPace, Setup};
use crate::{AppError, Context};
use mocomp_igtl::Timestamp;
use mocomp_k4a::clock::{DeviceClock, Gaps};
use mocomp_k4a::{Capture16, Device, K4aError, Playback};
use mocomp_vision::{Intrinsics, MarkerGeometry};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// When the feed started: on the monotonic clock and the wall clock, read together.
#[derive(Debug, Clone, Copy)]
struct Epoch {
    start: Instant,
    wall0: f64,
}

impl Epoch {
    fn now() -> Self {
        Self {
            start: Instant::now(),
            wall0: Timestamp::now().to_secs_f64(),
        }
    }

    /// A frame of `c` acquired at `t` s after the start.
    fn frame(self, c: Capture16, t: f64, dropped_before: u64) -> FeedEvent {
        let (Some(ir), Some(depth)) = (c.ir, c.depth) else {
            return FeedEvent::Incomplete;
        };
        let t = t.max(0.0);
        FeedEvent::Frame(Box::new(FeedFrame {
            width: ir.width,
            height: ir.height,
            ir: ir.data,
            depth: depth.data,
            acquired: self.start + Duration::from_secs_f64(t),
            acquired_unix_s: self.wall0 + t,
            t_s: t,
            dropped_before,
        }))
    }
}

/// A recording, played.
struct Played {
    playback: Playback,
    intrinsics: Intrinsics,
    pace: PlaybackPace,
    gaps: Gaps,
    epoch: Option<Epoch>,
    first_usec: u64,
}

impl Feed for Played {
    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn next(&mut self, stop: &AtomicBool) -> FeedEvent {
        let c = match self.playback.next_capture() {
            Ok(Some(c)) => c,
            Ok(None) => {
                return FeedEvent::End(FeedEnd::RecordingEnded, self.playback.path().to_string());
            }
            Err(e) => return FeedEvent::End(FeedEnd::RecordingDamaged, e.to_string()),
        };
        let Some(usec) = c.ir.as_ref().or(c.depth.as_ref()).map(|i| i.device_usec) else {
            return FeedEvent::Incomplete;
        };
        let epoch = *self.epoch.get_or_insert_with(|| {
            self.first_usec = usec;
            Epoch::now()
        });
        let dropped = self.gaps.dropped_before(usec);
        let t = match self.pace {
            PlaybackPace::RealTime => {
                // Delivered when its time comes, as the camera delivered it.
                let t = usec.saturating_sub(self.first_usec) as f64 * 1e-6;
                let due = epoch.start + Duration::from_secs_f64(t);
                while let Some(wait) = due.checked_duration_since(Instant::now()) {
                    if stop.load(Ordering::Relaxed) {
                        return FeedEvent::Idle;
                    }
                    std::thread::sleep(wait.min(Duration::from_millis(20)));
                }
                t
            }
            PlaybackPace::Fast => epoch.start.elapsed().as_secs_f64(),
        };
        epoch.frame(c, t, dropped)
    }
}

/// A device, streaming.
struct Live {
    device: Device,
    intrinsics: Intrinsics,
    clock: DeviceClock,
    gaps: Gaps,
    epoch: Epoch,
}

impl Feed for Live {
    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn next(&mut self, _stop: &AtomicBool) -> FeedEvent {
        // A short timeout, so a stop is seen soon.
        match self.device.next_capture(100) {
            Ok(None) => FeedEvent::Idle,
            Ok(Some(c)) => {
                let host_s = self.epoch.start.elapsed().as_secs_f64();
                let Some(usec) = c.ir.as_ref().or(c.depth.as_ref()).map(|i| i.device_usec) else {
                    return FeedEvent::Incomplete;
                };
                let dropped = self.gaps.dropped_before(usec);
                let t = self.clock.acquired(usec, host_s);
                self.epoch.frame(c, t, dropped)
            }
            Err(K4aError::DeviceLost) => {
                FeedEvent::End(FeedEnd::DeviceLost, K4aError::DeviceLost.to_string())
            }
            Err(e) => FeedEvent::End(FeedEnd::DeviceLost, e.to_string()),
        }
    }
}

/// A recording played as a feed, at `pace`: each frame stamped from the first capture's time
/// on, dropped frames counted by the timestamps, its end (or damage) the feed's end.
pub fn recording_feed(
    sdk: &Arc<mocomp_k4a::Sdk>,
    path: &std::path::Path,
    pace: PlaybackPace,
) -> Result<Box<dyn Feed>, AppError> {
    let name = path.display().to_string();
    let what = || format!("tracker.k4a.recording {name}");
    let playback = Playback::open(sdk, &name).what(what)?;
    playback.check_trackable().what(what)?;
    let intrinsics = playback.intrinsics().what(what)?;
    let fps = playback.info().fps;
    Ok(Box::new(Played {
        playback,
        intrinsics,
        pace,
        gaps: Gaps::new(fps),
        epoch: None,
        first_usec: 0,
    }))
}

/// Starts the Azure Kinect of `setup` (`[tracker.k4a]`: a recording, or a device) sharing
/// `link`, serving the head marker (`tracker.device`) on a free loopback port.
pub fn start(setup: &Setup, link: Arc<VisionLink>) -> Result<CameraServer, AppError> {
    let file = &setup.file;
    let k = &file.tracker.k4a;
    let geometry = match &k.geometry {
        Some(g) => crate::camera::frames::read_geometry(&setup.dir.join(g))
            .map_err(|e| AppError::Config(format!("tracker.k4a.geometry: {e}")))?,
        None => MarkerGeometry::ndi_8700449(),
    };
    let sdk_dir = k.sdk_dir.as_ref().map(|d| setup.dir.join(d));
    let sdk = crate::camera::k4a_recording::load_sdk(sdk_dir.as_deref())?;
    let feed: Box<dyn Feed> = match &k.recording {
        Some(r) => recording_feed(&sdk, &setup.dir.join(r), k.playback)?,
        None => {
            let mut device = Device::open(&sdk, k.serial.as_deref()).what(|| "tracker.k4a")?;
            let intrinsics = device
                .intrinsics(k.depth_mode)
                .what(|| format!("tracker.k4a: the calibration of {}", device.serial()))?;
            device
                .start(k.depth_mode, k.fps)
                .what(|| format!("tracker.k4a: starting {}", device.serial()))?;
            Box::new(Live {
                device,
                intrinsics,
                clock: DeviceClock::new(k.least_delay_s),
                gaps: Gaps::new(k.fps),
                epoch: Epoch::now(),
            })
        }
    };
    CameraServer::start(
        feed,
        geometry,
        &file.tracker.device,
        link,
        "tracker.k4a.params",
    )
}
