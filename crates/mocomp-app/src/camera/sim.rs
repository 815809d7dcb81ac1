//! The simulated depth camera (`tracker.source = "camera"`): IR + depth frames of the head
//! marker's fiducials rendered at the camera's rate (a Kinect v2's intrinsics, seen from the
//! tracker's place in the simulated world of `[tracker.simulated]`), as a [`Feed`] for
//! [`crate::camera::CameraServer`].

use crate::AppError;
use crate::camera::{CameraServer, Feed, FeedEvent, FeedFrame};
use crate::camera_link::VisionLink;
use crate::config::Setup;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_igtl::Timestamp;
use mocomp_vision::render::{Distractors, RenderOptions, render};
use mocomp_vision::{Intrinsics, MarkerGeometry};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// Frames rendered in real time.
struct Rendered {
    intrinsics: Intrinsics,
    geometry: MarkerGeometry,
    period_s: f64,
    seed: u64,
    distractors: Distractors,
    /// The head marker's true `tracker_from_marker` at a time since the start.
    truth: Box<dyn FnMut(f64) -> Isometry3<f64> + Send>,
    start: Option<(Instant, f64)>,
    frames: u64,
}

impl Feed for Rendered {
    fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    fn next(&mut self, stop: &AtomicBool) -> FeedEvent {
        let (start, wall0) = *self
            .start
            .get_or_insert_with(|| (Instant::now(), Timestamp::now().to_secs_f64()));
        let mut dropped = 0;
        loop {
            if stop.load(Ordering::Relaxed) {
                return FeedEvent::Idle;
            }
            let t = self.frames as f64 * self.period_s;
            let elapsed = start.elapsed().as_secs_f64();
            let wait = t - elapsed;
            if wait > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(wait.min(0.05)));
                continue;
            }
            if -wait > self.period_s {
                // Behind by a whole frame (a busy machine): the frames in between are dropped,
                // as a camera's are, rather than rendered late in a burst.
                let caught_up = (elapsed / self.period_s).floor() as u64;
                dropped += caught_up.saturating_sub(self.frames);
                self.frames = caught_up;
                continue;
            }
            let options = RenderOptions {
                intrinsics: self.intrinsics,
                distractors: self.distractors,
                ..RenderOptions::kinect((self.truth)(t), self.seed.wrapping_add(self.frames))
            };
            let r = render(&self.geometry, &options);
            self.frames += 1;
            return FeedEvent::Frame(Box::new(FeedFrame {
                width: r.width,
                height: r.height,
                ir: r.ir,
                depth: r.depth,
                acquired: start + Duration::from_secs_f64(t),
                acquired_unix_s: wall0 + t,
                t_s: t,
                dropped_before: dropped,
            }));
        }
    }
}

/// Starts the simulated camera of `setup` (its world, `[tracker.camera]`) sharing `link`,
/// serving the head marker (`tracker.device`) on a free loopback port.
pub fn start(setup: &Setup, link: Arc<VisionLink>) -> Result<CameraServer, AppError> {
    let file = &setup.file;
    let cam = &file.tracker.camera;
    let geometry = match &cam.geometry {
        Some(g) => crate::camera::frames::read_geometry(&setup.dir.join(g))
            .map_err(|e| AppError::Config(format!("tracker.camera.geometry: {e}")))?,
        None => MarkerGeometry::ndi_8700449(),
    };
    let s = &file.tracker.simulated;
    let tracker_from_base = s
        .base_from_tracker
        .as_ref()
        .map_or(setup.base_from_tracker, |y| y.iso())
        .inverse();
    let rest = s.base_from_head.iso();
    let trajectory = s.motion.trajectory();
    let feed = Rendered {
        intrinsics: Intrinsics::kinect_v2(),
        geometry: geometry.clone(),
        period_s: 1.0 / cam.rate_hz,
        seed: cam.seed,
        distractors: Distractors {
            sun_spots: cam.sun_spots,
            reflections: cam.reflections,
            hand: false,
            placement_seed: Some(cam.seed),
        },
        truth: Box::new(move |t| tracker_from_base * rest * trajectory.rest_from_head(t)),
        start: None,
        frames: 0,
    };
    CameraServer::start(
        Box::new(feed),
        geometry,
        &file.tracker.device,
        link,
        "tracker.camera.params",
    )
}
