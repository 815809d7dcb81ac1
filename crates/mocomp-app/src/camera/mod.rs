//! A depth camera as a tracker: the paper's tracking path, live.
//!
//! A thread takes each IR + depth frame from a [`Feed`] (the simulated camera of
//! [`crate::camera::sim`], or an Azure Kinect device or recording of [`crate::camera::k4a`]),
//! tracks it with the paper's pipeline (`mocomp-vision`: threshold, depth range, blobs, depth
//! ring, matching, registration), and serves the pose over OpenIGTLink on loopback, stamped with
//! the frame's acquisition time, as a tracking server does (invalid when the marker was not
//! found). The loop reads it like any tracker. The pipeline's parameters can change while it
//! runs ([`VisionLink::set_params`], the console's tuning); the newest frame with its result is
//! kept for the console's preview ([`VisionLink::overlay_png`]). Dropped frames and the feed's
//! end (an unplugged device, a recording's end or damage) go to the run's notes and report.

pub mod frames;
pub mod k4a;
pub mod k4a_recording;
pub mod k4a_writer;
pub mod sim;

use crate::camera_link::{CameraNote, FeedEnd, Preview, VisionLink, lock};
use crate::frontend::Note;
use crate::{AppError, Context};
use mocomp_geom::Clock;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use mocomp_vision::{Frame, Intrinsics, MarkerGeometry, Tracker};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::SyncSender;
use std::sync::{Arc, Mutex, OnceLock};
use std::thread::JoinHandle;
use std::time::Instant;

/// One frame from a feed.
#[derive(Debug, Clone)]
pub struct FeedFrame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// IR image.
    pub ir: Vec<u16>,
    /// Depth image, mm.
    pub depth: Vec<u16>,
    /// When it was acquired (the middle of its exposure), on this host's monotonic clock.
    pub acquired: Instant,
    /// The same, s since the Unix epoch (what goes out over OpenIGTLink).
    pub acquired_unix_s: f64,
    /// Seconds since the feed started (the preview's time).
    pub t_s: f64,
    /// Frames missing before this one.
    pub dropped_before: u64,
}

/// What a feed gave.
#[derive(Debug)]
pub enum FeedEvent {
    /// A frame.
    Frame(Box<FeedFrame>),
    /// A capture without IR or depth (skipped: the pipeline needs both).
    Incomplete,
    /// Nothing yet (a device's timeout, or the stop was asked for).
    Idle,
    /// No more frames, and why (with the error's words).
    End(FeedEnd, String),
}

/// Where a camera's frames come from. `next` may block, briefly (it returns `Idle` when `stop`
/// is set).
pub trait Feed: Send {
    /// The camera's intrinsics.
    fn intrinsics(&self) -> Intrinsics;
    /// The next frame.
    fn next(&mut self, stop: &AtomicBool) -> FeedEvent;
}

/// The camera's figures over the run.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct CameraReport {
    /// Frames tracked.
    pub frames: u64,
    /// Frames in which the marker was found.
    pub found: u64,
    /// Frames missing (by their timestamps, or skipped when the camera fell behind).
    pub dropped: u64,
    /// Captures without IR or depth.
    pub incomplete: u64,
    /// From acquisition to the pose sent, median and 99th percentile, ms.
    pub latency_median_ms: f64,
    /// The same, 99th percentile.
    pub latency_p99_ms: f64,
    /// Why the camera stopped before the run did, if it did.
    pub ended: Option<FeedEnd>,
    /// The error's words, with `ended`.
    pub ended_detail: Option<String>,
}

/// The camera's counters, shared with the server.
#[derive(Default)]
struct Shared {
    report: Mutex<CameraReport>,
    latencies_s: Mutex<Vec<f64>>,
    notes: OnceLock<(SyncSender<Note>, Arc<dyn Clock>)>,
}

impl std::fmt::Debug for Shared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shared")
            .field("report", &self.report)
            .finish_non_exhaustive()
    }
}

/// Latency samples kept (about an hour at 30 frames a second).
const LATENCIES: usize = 100_000;

/// The camera, running. Stops when dropped.
#[derive(Debug)]
pub struct CameraServer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    shared: Arc<Shared>,
}

/// What the camera's thread needs.
struct Camera {
    server: Server,
    device: String,
    geometry: MarkerGeometry,
    feed: Box<dyn Feed>,
    link: Arc<VisionLink>,
    shared: Arc<Shared>,
}

impl CameraServer {
    /// Starts a camera on `feed` tracking `geometry`, sharing `link` (its parameters as
    /// `params_key` names them), serving the head marker as `device` on a free loopback port.
    pub fn start(
        feed: Box<dyn Feed>,
        geometry: MarkerGeometry,
        device: &str,
        link: Arc<VisionLink>,
        params_key: &str,
    ) -> Result<Self, AppError> {
        // A tracker that cannot be made from these parameters is named now, not per frame.
        Tracker::new(feed.intrinsics(), link.params(), geometry.clone())
            .map_err(|e| AppError::Config(format!("{params_key}: {e}")))?;
        let server = Server::bind("127.0.0.1:0", ServerConfig::default())
            .what(|| "the depth camera's OpenIGTLink server")?;
        let addr = server.local_addr();
        let shared = Arc::new(Shared::default());
        let camera = Camera {
            server,
            device: device.to_string(),
            geometry,
            feed,
            link,
            shared: Arc::clone(&shared),
        };
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("depth-camera".into())
            .spawn(move || camera.run(&stop2))
            .what(|| "starting the depth camera")?;
        Ok(Self {
            addr,
            stop,
            thread: Some(thread),
            shared,
        })
    }

    /// The OpenIGTLink address it serves.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Sends the camera's notes (dropped frames, its end) to the run's, stamped on `clock`.
    pub fn notify(&self, notes: SyncSender<Note>, clock: Arc<dyn Clock>) {
        self.shared.notes.set((notes, clock)).ok();
    }

    /// The figures so far.
    pub fn report(&self) -> CameraReport {
        let mut r = lock(&self.shared.report).clone();
        let mut l = lock(&self.shared.latencies_s).clone();
        if !l.is_empty() {
            l.sort_by(f64::total_cmp);
            let at = |p: f64| l[((l.len() - 1) as f64 * p).round() as usize] * 1e3;
            r.latency_median_ms = at(0.5);
            r.latency_p99_ms = at(0.99);
        }
        r
    }
}

impl Shared {
    fn note(&self, n: CameraNote) {
        if let Some((tx, clock)) = self.notes.get() {
            // A full channel drops the note (the report still counts it).
            tx.try_send(Note::Camera(clock.now_s(), n)).ok();
        }
    }
}

impl Camera {
    fn run(mut self, stop: &AtomicBool) {
        let mut version = self.link.params_version();
        let intrinsics = self.feed.intrinsics();
        let mut tracker = Tracker::new(intrinsics, self.link.params(), self.geometry.clone()).ok();
        let mut last_pose: Option<Isometry3<f64>> = None;
        while !stop.load(Ordering::Relaxed) {
            let f = match self.feed.next(stop) {
                FeedEvent::Frame(f) => f,
                FeedEvent::Idle => continue,
                FeedEvent::Incomplete => {
                    lock(&self.shared.report).incomplete += 1;
                    continue;
                }
                FeedEvent::End(why, detail) => {
                    {
                        let mut r = lock(&self.shared.report);
                        r.ended = Some(why);
                        r.ended_detail = Some(detail);
                    }
                    self.shared.note(CameraNote::Ended(why));
                    break;
                }
            };
            if f.dropped_before > 0 {
                lock(&self.shared.report).dropped += f.dropped_before;
                self.shared.note(CameraNote::Dropped(f.dropped_before));
            }
            let now_version = self.link.params_version();
            if now_version != version {
                // Checked when they were set: a tracker is always made from them.
                tracker = Tracker::new(intrinsics, self.link.params(), self.geometry.clone()).ok();
                version = now_version;
            }
            let Some(tracker) = tracker.as_mut() else {
                continue;
            };
            let Ok(frame) = Frame::new(f.width, f.height, &f.ir, &f.depth) else {
                lock(&self.shared.report).incomplete += 1;
                continue;
            };
            let Ok(result) = tracker.process(&frame) else {
                continue;
            };
            let (pose, status) = match &result.detection {
                Some(d) => {
                    last_pose = Some(d.tracker_from_marker);
                    (d.tracker_from_marker, "OK")
                }
                None => (last_pose.unwrap_or_else(Isometry3::identity), "INVALID"),
            };
            if let Ok(m) = Message::transform(
                &self.device,
                &pose,
                Timestamp::from_secs_f64(f.acquired_unix_s),
            ) {
                self.server
                    .send(&m.with_metadata(vec![MetaEntry::text("TransformStatus", status)]));
            }
            let latency = Instant::now()
                .saturating_duration_since(f.acquired)
                .as_secs_f64();
            let (frames, found) = {
                let mut r = lock(&self.shared.report);
                r.frames += 1;
                r.found += u64::from(result.detection.is_some());
                (r.frames, r.found)
            };
            {
                let mut l = lock(&self.shared.latencies_s);
                if l.len() < LATENCIES {
                    l.push(latency);
                }
            }
            let scan_area = tracker.scan_area();
            let FeedFrame {
                width,
                height,
                ir,
                depth,
                t_s,
                ..
            } = *f;
            self.link.show(Preview {
                t_s,
                frames,
                found,
                width,
                height,
                ir,
                depth,
                scan_area,
                result,
            });
        }
        self.server.stop();
    }
}

impl Drop for CameraServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join().ok();
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::MonotonicClock;
    use mocomp_vision::render::{RenderOptions, render, view_pose};
    use std::collections::VecDeque;
    use std::time::Duration;

    /// A feed that plays a script once told to go, then idles.
    struct Script(VecDeque<FeedEvent>, Arc<AtomicBool>);

    impl Feed for Script {
        fn intrinsics(&self) -> Intrinsics {
            Intrinsics::kinect_v2()
        }
        fn next(&mut self, _stop: &AtomicBool) -> FeedEvent {
            if !self.1.load(Ordering::Acquire) {
                std::thread::sleep(Duration::from_millis(1));
                return FeedEvent::Idle;
            }
            self.0.pop_front().unwrap_or_else(|| {
                std::thread::sleep(Duration::from_millis(5));
                FeedEvent::Idle
            })
        }
    }

    fn frame(k: u64, dropped_before: u64) -> FeedEvent {
        let r = render(
            &MarkerGeometry::ndi_8700449(),
            &RenderOptions::kinect(view_pose(k), k),
        );
        FeedEvent::Frame(Box::new(FeedFrame {
            width: r.width,
            height: r.height,
            ir: r.ir,
            depth: r.depth,
            acquired: Instant::now(),
            acquired_unix_s: Timestamp::now().to_secs_f64(),
            t_s: k as f64 / 30.0,
            dropped_before,
        }))
    }

    #[test]
    fn drops_and_a_lost_device_are_counted_and_named_in_the_notes() {
        let go = Arc::new(AtomicBool::new(false));
        let script = Script(
            VecDeque::from(vec![
                frame(1, 0),
                FeedEvent::Incomplete,
                frame(2, 3),
                frame(3, 0),
                FeedEvent::End(FeedEnd::DeviceLost, "unplugged".into()),
            ]),
            Arc::clone(&go),
        );
        let link = VisionLink::new(mocomp_vision::TrackParams::default());
        let camera = CameraServer::start(
            Box::new(script),
            MarkerGeometry::ndi_8700449(),
            "Head",
            Arc::clone(&link),
            "params",
        )
        .unwrap();
        let (tx, rx) = std::sync::mpsc::sync_channel(16);
        camera.notify(tx, Arc::new(MonotonicClock::new()));
        go.store(true, Ordering::Release);
        let end = Instant::now() + Duration::from_secs(10);
        while camera.report().ended.is_none() && Instant::now() < end {
            std::thread::sleep(Duration::from_millis(5));
        }
        let r = camera.report();
        assert_eq!(
            (r.frames, r.dropped, r.incomplete, r.ended),
            (3, 3, 1, Some(FeedEnd::DeviceLost)),
            "{r:?}"
        );
        assert_eq!(r.found, 3, "{r:?}");
        assert_eq!(r.ended_detail.as_deref(), Some("unplugged"));
        assert!(r.latency_median_ms >= 0.0 && r.latency_p99_ms >= r.latency_median_ms);
        let notes: Vec<Note> = rx.try_iter().collect();
        let ended = notes
            .iter()
            .any(|n| matches!(n, Note::Camera(_, CameraNote::Ended(FeedEnd::DeviceLost))));
        assert!(ended, "{notes:?}");
        assert_eq!(
            CameraNote::Ended(FeedEnd::DeviceLost).to_string(),
            "depth camera: the camera stopped delivering frames (unplugged?); no more head poses"
        );
        assert!(link.preview().is_some());
    }
}
