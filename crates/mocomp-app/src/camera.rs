//! The simulated depth camera (`tracker.source = "camera"`): the paper's tracking path, live.
//!
//! A thread renders an IR + depth frame of the head marker's fiducials (a Kinect v2's
//! intrinsics, seen from the tracker's place in the simulated world) at the camera's rate, tracks
//! it with the paper's pipeline (`mocomp-vision`: threshold, depth range, blobs, depth ring,
//! matching, registration), and serves the pose over OpenIGTLink on loopback, stamped with the
//! frame's acquisition time, as a tracking server does (invalid when the marker was not found).
//! The loop reads it like any tracker. The pipeline's parameters can change while it runs
//! ([`VisionLink::set_params`], the console's tuning); the newest frame with its result is kept
//! for the console's preview ([`VisionLink::overlay_png`]).

use crate::config::Setup;
use crate::{AppError, Context};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use mocomp_vision::render::{Distractors, RenderOptions, render};
use mocomp_vision::{Frame, FrameResult, Intrinsics, MarkerGeometry, TrackParams, Tracker};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The newest frame and what the pipeline made of it.
#[derive(Debug, Clone)]
pub struct Preview {
    /// Seconds since the camera started.
    pub t_s: f64,
    /// Frames taken so far.
    pub frames: u64,
    /// Frames in which the marker was found so far.
    pub found: u64,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// IR image.
    pub ir: Vec<u16>,
    /// Depth image, mm.
    pub depth: Vec<u16>,
    /// The scan area the pipeline used.
    pub scan_area: [u32; 4],
    /// The pipeline's result.
    pub result: FrameResult,
}

/// What the camera and a front end share: the pipeline's parameters (a front end may change
/// them; the camera takes them before its next frame) and the newest frame.
#[derive(Debug)]
pub struct VisionLink {
    params: Mutex<TrackParams>,
    version: AtomicU64,
    preview: Mutex<Option<Arc<Preview>>>,
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

impl VisionLink {
    /// A link with these parameters and no frame yet.
    pub fn new(params: TrackParams) -> Arc<Self> {
        Arc::new(Self {
            params: Mutex::new(params),
            version: AtomicU64::new(0),
            preview: Mutex::new(None),
        })
    }

    /// The parameters in force.
    pub fn params(&self) -> TrackParams {
        *lock(&self.params)
    }

    /// New parameters, for the next frame; checked as the configuration file checks them.
    pub fn set_params(&self, params: TrackParams) -> Result<(), AppError> {
        params
            .validate("tracker.camera.params")
            .map_err(|e| AppError::Config(e.to_string()))?;
        *lock(&self.params) = params;
        self.version.fetch_add(1, Ordering::Release);
        Ok(())
    }

    /// The newest frame with its result.
    pub fn preview(&self) -> Option<Arc<Preview>> {
        lock(&self.preview).clone()
    }

    /// The newest frame with the paper's overlays (scan area, blobs with boxes, fiducials
    /// numbered, rejected blobs crossed) as a PNG; `None` before the first frame.
    pub fn overlay_png(&self) -> Result<Option<Vec<u8>>, AppError> {
        let Some(p) = self.preview() else {
            return Ok(None);
        };
        let frame = Frame::new(p.width, p.height, &p.ir, &p.depth).what(|| "the camera's frame")?;
        let img = mocomp_vision::overlay::overlay(&frame, p.scan_area, &p.result);
        mocomp_vision::codec::encode_rgb_png(img.width, img.height, &img.data, "overlay")
            .map(Some)
            .what(|| "encoding the camera's overlay")
    }
}

/// The camera, running. Stops when dropped.
#[derive(Debug)]
pub struct CameraServer {
    addr: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

/// What the camera's thread needs.
struct Camera {
    server: Server,
    device: String,
    intrinsics: Intrinsics,
    geometry: MarkerGeometry,
    period_s: f64,
    seed: u64,
    distractors: Distractors,
    /// The head marker's true `tracker_from_marker` at a time since the start.
    truth: Box<dyn FnMut(f64) -> Isometry3<f64> + Send>,
    link: Arc<VisionLink>,
}

impl CameraServer {
    /// Starts the camera of `setup` (its world, `[tracker.camera]`) sharing `link`, serving the
    /// head marker (`tracker.device`) on a free loopback port.
    pub fn start(setup: &Setup, link: Arc<VisionLink>) -> Result<Self, AppError> {
        let file = &setup.file;
        let cam = &file.tracker.camera;
        let geometry = match &cam.geometry {
            Some(g) => crate::frames::read_geometry(&setup.dir.join(g))
                .map_err(|e| AppError::Config(format!("tracker.camera.geometry: {e}")))?,
            None => MarkerGeometry::ndi_8700449(),
        };
        let intrinsics = Intrinsics::kinect_v2();
        // A tracker that cannot be made from these parameters is named now, not per frame.
        Tracker::new(intrinsics, link.params(), geometry.clone())
            .map_err(|e| AppError::Config(format!("tracker.camera.params: {e}")))?;
        let s = &file.tracker.simulated;
        let tracker_from_base = s
            .base_from_tracker
            .as_ref()
            .map_or(setup.base_from_tracker, |y| y.iso())
            .inverse();
        let rest = s.base_from_head.iso();
        let trajectory = s.motion.trajectory();
        let server = Server::bind("127.0.0.1:0", ServerConfig::default())
            .what(|| "the simulated camera's OpenIGTLink server")?;
        let addr = server.local_addr();
        let camera = Camera {
            server,
            device: file.tracker.device.clone(),
            intrinsics,
            geometry,
            period_s: 1.0 / cam.rate_hz,
            seed: cam.seed,
            distractors: Distractors {
                sun_spots: cam.sun_spots,
                reflections: cam.reflections,
                hand: false,
                placement_seed: Some(cam.seed),
            },
            truth: Box::new(move |t| tracker_from_base * rest * trajectory.rest_from_head(t)),
            link,
        };
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("sim-camera".into())
            .spawn(move || camera.run(&stop2))
            .what(|| "starting the simulated camera")?;
        Ok(Self {
            addr,
            stop,
            thread: Some(thread),
        })
    }

    /// The OpenIGTLink address it serves.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }
}

impl Camera {
    fn run(mut self, stop: &AtomicBool) {
        let start = Instant::now();
        let wall0 = Timestamp::now().to_secs_f64();
        let mut version = self.link.version.load(Ordering::Acquire);
        let mut tracker =
            Tracker::new(self.intrinsics, self.link.params(), self.geometry.clone()).ok();
        let (mut frames, mut found) = (0u64, 0u64);
        let mut last_pose: Option<Isometry3<f64>> = None;
        while !stop.load(Ordering::Relaxed) {
            let t = frames as f64 * self.period_s;
            let elapsed = start.elapsed().as_secs_f64();
            let wait = t - elapsed;
            if wait > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(wait.min(0.05)));
                continue;
            }
            if -wait > self.period_s {
                // Behind by a whole frame (a busy machine): the frames in between are dropped,
                // as a camera's are, rather than rendered late in a burst.
                frames = (elapsed / self.period_s).floor() as u64;
                continue;
            }
            let now_version = self.link.version.load(Ordering::Acquire);
            if now_version != version {
                // Checked when they were set: a tracker is always made from them.
                tracker =
                    Tracker::new(self.intrinsics, self.link.params(), self.geometry.clone()).ok();
                version = now_version;
            }
            let options = RenderOptions {
                intrinsics: self.intrinsics,
                distractors: self.distractors,
                ..RenderOptions::kinect((self.truth)(t), self.seed.wrapping_add(frames))
            };
            let r = render(&self.geometry, &options);
            frames += 1;
            let Some(tracker) = tracker.as_mut() else {
                continue;
            };
            let Ok(frame) = Frame::new(r.width, r.height, &r.ir, &r.depth) else {
                continue;
            };
            let Ok(result) = tracker.process(&frame) else {
                continue;
            };
            let ts = Timestamp::from_secs_f64(wall0 + t);
            let (pose, status) = match &result.detection {
                Some(d) => {
                    found += 1;
                    last_pose = Some(d.tracker_from_marker);
                    (d.tracker_from_marker, "OK")
                }
                None => (last_pose.unwrap_or_else(Isometry3::identity), "INVALID"),
            };
            if let Ok(m) = Message::transform(&self.device, &pose, ts) {
                self.server
                    .send(&m.with_metadata(vec![MetaEntry::text("TransformStatus", status)]));
            }
            let scan_area = tracker.scan_area();
            *lock(&self.link.preview) = Some(Arc::new(Preview {
                t_s: t,
                frames,
                found,
                width: r.width,
                height: r.height,
                ir: r.ir,
                depth: r.depth,
                scan_area,
                result,
            }));
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
