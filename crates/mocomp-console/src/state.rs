//! What the console knows of the running loop, and the observer that tells it. The observer runs
//! on the live loop's logger thread (never on the loop's own), takes every cycle record from
//! there, and publishes a status 25 times a second: to the WebSocket through a `watch` channel,
//! and to the HTTP API through a small store. Units leave here in millimetres and degrees, the
//! console's display units, named in every field.

use mocomp_app::config::{Config, Setup};
use mocomp_app::frontend::{Controls, Note, Observer, Status, mode_name};
use mocomp_control::{CycleRecord, Event, HeadModel, LoopConfig, Mode, Reason};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_head::Mesh;
use mocomp_kin::Arm;
use mocomp_session::{GateEvent, GateState, shut_reason};
use serde::Serialize;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::{SystemTime, UNIX_EPOCH};
use tokio::sync::watch;

/// Statuses published per second of loop time.
pub const STATUS_RATE_HZ: f64 = 25.0;
/// Seconds of deviation and head speed the plot shows.
pub const HISTORY_S: f64 = 30.0;
/// Events kept for a page that opens late.
const EVENTS_KEPT: usize = 500;
/// Seconds of the loop's head estimates and joints kept for teaching the goal.
const TEACH_WINDOW_S: f64 = 0.5;

/// A pose for the 3-D view: position (mm) and rotation matrix (rows), in the robot's base frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PoseJson {
    /// Position, mm.
    pub p_mm: [f64; 3],
    /// Rotation matrix, rows.
    pub r: [[f64; 3]; 3],
}

impl PoseJson {
    /// From an isometry in metres.
    pub fn from_iso(iso: &Isometry3<f64>) -> Self {
        let t = iso.translation.vector * 1e3;
        let m = iso.rotation.to_rotation_matrix();
        Self {
            p_mm: [t.x, t.y, t.z],
            r: std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)])),
        }
    }
}

/// Where things are now, in the base frame.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneNow {
    /// The arm's joint frames' origins, base to flange, mm (from FK of the measured joints).
    pub links_mm: Vec<[f64; 3]>,
    /// The coil where it is (FK of the measured joints, its mounting).
    pub coil: Option<PoseJson>,
    /// The coil at its goal on the head the loop predicts.
    pub goal: Option<PoseJson>,
    /// The head the loop predicts (its marker's frame).
    pub head: Option<PoseJson>,
    /// The coil and its goal on the patient's image, for the MRI's slices.
    pub image: Option<ImageNow>,
}

/// The coil and its goal in the image's frame (RAS, mm), as the MRI's slices draw them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImageNow {
    /// The measured coil, when the head is known.
    pub coil: Option<crate::mri::CoilInImage>,
    /// The goal: the selected target.
    pub goal: crate::mri::CoilInImage,
}

/// The camera pipeline's newest frame, for a session on the simulated camera.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraJson {
    /// Frames taken.
    pub frames: u64,
    /// Frames in which the marker was found.
    pub found: u64,
    /// Whether the newest frame found it.
    pub found_now: bool,
    /// Its registration error, mm.
    pub fre_mm: Option<f64>,
    /// Blobs in the newest frame.
    pub blobs: usize,
    /// Why the newest frame has no pose.
    pub not_found: Option<String>,
}

impl CameraJson {
    fn of(p: &mocomp_app::camera_link::Preview) -> Self {
        Self {
            frames: p.frames,
            found: p.found,
            found_now: p.result.detection.is_some(),
            fre_mm: p.result.detection.as_ref().map(|d| d.fre_m * 1e3),
            blobs: p.result.blobs.len(),
            not_found: p.result.not_found.as_ref().map(ToString::to_string),
        }
    }
}

/// A calibration collection's progress (`mocomp calibrate collect --dashboard`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CalibrationJson {
    /// waiting (for the operator's go), collecting, done, failed.
    pub state: &'static str,
    /// Poses planned.
    pub planned: usize,
    /// Poses done.
    pub done: usize,
    /// Poses (1-based) where the marker was not seen.
    pub missed: Vec<usize>,
    /// The outcome: the solution's residuals and where it was saved, or why it failed.
    pub message: Option<String>,
}

/// A navigation task's progress (`mocomp register --dashboard`, `mocomp pointer calibrate
/// --dashboard`): what the operator must do now, what is in, and the outcome.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NavigationJson {
    /// registration, pivot.
    pub task: &'static str,
    /// waiting (for the operator's go), running, done, failed.
    pub state: &'static str,
    /// What the operator does now ("touch the nasion and hold still").
    pub step: String,
    /// The landmarks touched so far and how far the burst's tips spread, mm.
    pub landmarks: Vec<(String, f64)>,
    /// Samples (swept points, pivot poses) in, of how many.
    pub samples: [usize; 2],
    /// The outcome, a line each (FRE per landmark, surface RMS, the target error at each
    /// target; the tip and its error), or why it failed.
    pub result: Vec<String>,
}

/// The status the page shows (`GET /api/status`, and each WebSocket message).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StatusJson {
    /// Loop time, s.
    pub t: f64,
    /// The mode's kind: tracking, approaching, holding, faulted, retreating (or starting).
    pub mode: String,
    /// Why, when the mode has a reason: the rule's code for a loop's mode (`Operator`,
    /// `NoPath(0.156…)`), words for a phase that is not the loop's.
    pub reason: Option<String>,
    /// The same in words with units (what the page shows).
    pub reason_text: Option<String>,
    /// The mode with its reason, as the log writes it.
    pub mode_text: String,
    /// Cycles per second over the last status interval.
    pub rate_hz: f64,
    /// Prediction horizon, ms.
    pub horizon_ms: f64,
    /// The newest tracker sample's age, ms.
    pub sample_age_ms: f64,
    /// From the cycle's start to its command acting, ms.
    pub command_delay_ms: f64,
    /// The measured coil's distance from its goal, mm.
    pub deviation_mm: f64,
    /// The same, rotation, degrees.
    pub deviation_deg: f64,
    /// The head's speed, mm/s.
    pub head_speed_mm_s: f64,
    /// The head's rotation speed, °/s.
    pub head_speed_deg_s: f64,
    /// The commanded coil's clearance from the predicted head, mm.
    pub clearance_mm: f64,
    /// The standoff the goal is backed off by, mm.
    pub standoff_mm: f64,
    /// Contact force, N (none without `loop.force_sensing`).
    pub force_n: Option<f64>,
    /// The dose the measured coil gives at the goal's target, % of the planned (none without
    /// a coil model or a plan for the goal).
    pub dose_pct: Option<f64>,
    /// The same in V/m.
    pub dose_v_per_m: Option<f64>,
    /// Whether the operator holds the loop.
    pub operator_hold: bool,
    /// Free-drive is on (the arm yields to the operator's hand).
    pub freedrive: bool,
    /// Whether the loop runs (false once it has ended).
    pub running: bool,
    /// Wall-clock time of the cycle this status is from, ms since the Unix epoch (the page
    /// measures its latency against it).
    pub cycle_unix_ms: f64,
    /// The camera pipeline's newest frame (a session on the simulated camera).
    pub camera: Option<CameraJson>,
    /// A calibration collection's progress (a `calibrate collect` session).
    pub calibration: Option<CalibrationJson>,
    /// A navigation task's progress (a `register` or `pointer calibrate` session).
    pub navigation: Option<NavigationJson>,
    /// The controller running (in the experiment: `paper` or `mocomp`).
    pub controller: Option<&'static str>,
    /// The scene's version ([`SceneJson::version`]).
    pub scene_version: u64,
    /// Where things are.
    pub scene: SceneNow,
    /// The session's gate and pulses, once it has reported either.
    pub session: Option<SessionNow>,
}

/// The session's gate and pulses, for the page's tiles.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SessionNow {
    /// Whether the gate is open (pulses allowed).
    pub gate_open: bool,
    /// Why it is shut, in words (empty when open or not yet judged).
    pub gate_why: String,
    /// Pulses so far.
    pub pulses: u64,
    /// Of them, with the gate shut.
    pub pulses_off_target: u64,
    /// The last pulse: its position and angle error (mm, °) and whether the gate was open.
    pub last_pulse: Option<(f64, f64, bool)>,
}

impl StatusJson {
    fn starting() -> Self {
        Self {
            t: 0.0,
            mode: "starting".into(),
            reason: None,
            reason_text: None,
            mode_text: "starting".into(),
            rate_hz: 0.0,
            horizon_ms: f64::NAN,
            sample_age_ms: f64::NAN,
            command_delay_ms: f64::NAN,
            deviation_mm: f64::NAN,
            deviation_deg: f64::NAN,
            head_speed_mm_s: f64::NAN,
            head_speed_deg_s: f64::NAN,
            clearance_mm: f64::NAN,
            standoff_mm: f64::NAN,
            force_n: None,
            dose_pct: None,
            dose_v_per_m: None,
            operator_hold: false,
            freedrive: false,
            running: true,
            cycle_unix_ms: f64::NAN,
            camera: None,
            calibration: None,
            navigation: None,
            controller: None,
            scene_version: 0,
            scene: SceneNow {
                links_mm: Vec::new(),
                coil: None,
                goal: None,
                head: None,
                image: None,
            },
            session: None,
        }
    }
}

/// One event for the page's log.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EventJson {
    /// Loop time, s.
    pub t: f64,
    /// hold, retreat, resume, reached, outlier, coasting, transit; session (a pulse, the gate, the drift
    /// monitor: the text says which).
    pub kind: &'static str,
    /// The rule that fired, if any, by its code.
    pub reason: Option<String>,
    /// The event in words with units (what the page shows).
    pub text: String,
}

impl EventJson {
    fn new(t: f64, e: &Event) -> Self {
        let (kind, reason) = match e {
            Event::Hold(r) => ("hold", Some(rule_code(r))),
            Event::Retreat(r) => ("retreat", Some(rule_code(r))),
            Event::Resume => ("resume", None),
            Event::Reached => ("reached", None),
            Event::Outlier(..) => ("outlier", None),
            Event::Coasting(..) => ("coasting", None),
            Event::Transit(..) => ("transit", None),
            Event::Rearmed => ("rearmed", None),
        };
        Self {
            t,
            kind,
            reason,
            text: e.to_string(),
        }
    }
}

/// A reason's code: its rule's name and values (`NoPath(0.156…)`), for the API's clients; the
/// page shows its words ([`Reason`]'s `Display`).
pub fn rule_code(r: &Reason) -> String {
    format!("{r:?}")
}

/// The scene's fixed parts (`GET /api/scene`), in the base frame, mm.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneJson {
    /// Changes when the scene is replaced (the status carries it: a page fetches the scene
    /// again).
    pub version: u64,
    /// The robot model.
    pub robot: String,
    /// The tracker, base_from_tracker.
    pub tracker: PoseJson,
    /// The head model: an ellipsoid in the head marker's frame (head_from_ellipsoid), semi-axes.
    pub head_from_ellipsoid: PoseJson,
    /// The ellipsoid's semi-axes, mm.
    pub head_radii_mm: [f64; 3],
    /// The patient's scalp instead of the ellipsoid, decimated for the page (head marker's
    /// frame, mm).
    pub head_mesh: Option<MeshJson>,
    /// The coil's radius, mm.
    pub coil_radius_mm: f64,
    /// The coil's thickness, mm.
    pub coil_thickness_mm: f64,
    /// The coil's casing as the head sees it, where one is given: its outline at its face (coil
    /// frame, mm), drawn in place of the cylinder's rim.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coil_outline_mm: Option<Vec<[f64; 3]>>,
}

/// A head mesh for the page: vertices (mm) and triangles.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshJson {
    /// Vertices, mm, rounded to 0.1 mm.
    pub vertices_mm: Vec<[f32; 3]>,
    /// Triangles, indices into the vertices.
    pub triangles: Vec<[u32; 3]>,
}

/// The most triangles the page draws of a scalp.
pub const PAGE_TRIANGLES: usize = 3000;

/// What the page draws of `head`: the ellipsoid's pose and semi-axes (mm), or the scalp.
/// A casing's outline for the page, mm, to 0.1 mm.
fn outline_json(casing: &mocomp_head::casing::Casing) -> Vec<[f64; 3]> {
    let mm = |x: f64| (x * 1e4).round() / 10.0;
    casing
        .outline()
        .iter()
        .map(|p| [mm(p.x), mm(p.y), mm(p.z)])
        .collect()
}

fn head_json(head: &HeadModel) -> (PoseJson, [f64; 3], Option<MeshJson>) {
    if let Some(e) = head.as_ellipsoid() {
        let r = e.radii() * 1e3;
        return (
            PoseJson::from_iso(e.head_from_ellipsoid()),
            [r.x, r.y, r.z],
            None,
        );
    }
    let mesh = head.shape().scalp().map_or_else(Mesh::default, |m| {
        Mesh {
            vertices: m.vertices().to_vec(),
            triangles: m.triangles().to_vec(),
        }
        .decimated(PAGE_TRIANGLES)
    });
    let round = |x: f64| ((x * 1e4).round() / 10.0) as f32;
    let json = MeshJson {
        vertices_mm: mesh
            .vertices
            .iter()
            .map(|p| [round(p.x), round(p.y), round(p.z)])
            .collect(),
        triangles: mesh.triangles,
    };
    (
        PoseJson::from_iso(&Isometry3::identity()),
        [0.0; 3],
        Some(json),
    )
}

#[derive(Debug)]
struct Store {
    /// The loop's last [`TEACH_WINDOW_S`] of (tracker_from_head, joints), oldest first.
    teach_window: Vec<(Isometry3<f64>, [f64; 6])>,
    status: StatusJson,
    events: VecDeque<EventJson>,
    /// (t s, deviation mm, head speed mm/s), the last [`HISTORY_S`].
    history: VecDeque<[f64; 3]>,
    config: Config,
}

/// What the server and the observer share.
#[derive(Debug)]
pub struct Shared {
    /// The loop's controls.
    pub controls: Arc<Controls>,
    /// The session's setup (its frames, its file).
    pub setup: Setup,
    /// The fixed scene (replaced when an experiment's run places its own).
    scene: Mutex<SceneJson>,
    /// The patient's MRI, when `[head] mesh` is one.
    pub mri: crate::mri::MriView,
    store: Mutex<Store>,
    status_tx: watch::Sender<Published>,
    /// When the console started (the calibration's events are timed from it).
    started: std::time::Instant,
    /// Each open stream's newest status sent (a version of [`Published`]); a stream gone is
    /// dropped here the next time it is looked at.
    streams: Mutex<Vec<std::sync::Weak<AtomicU64>>>,
}

/// A status as JSON text, with its version (counting every publish).
#[derive(Debug, Clone)]
pub struct Published {
    /// Counts the publishes.
    pub version: u64,
    /// The status.
    pub text: Arc<str>,
}

impl Shared {
    /// The state of a session on `setup`, steered through `controls`.
    pub fn new(setup: &Setup, controls: Arc<Controls>) -> Arc<Self> {
        let file = &setup.file;
        let status = StatusJson::starting();
        let text: Arc<str> = serde_json::to_string(&status).unwrap_or_default().into();
        let (status_tx, _) = watch::channel(Published { version: 0, text });
        let (head_from_ellipsoid, head_radii_mm, head_mesh) = match file.head_model() {
            Ok(h) => head_json(&h),
            Err(_) => (
                PoseJson::from_iso(&file.head.head_from_ellipsoid.iso()),
                file.head.radii_m.map(|r| r * 1e3),
                None,
            ),
        };
        Arc::new(Self {
            controls,
            mri: crate::mri::MriView::of(setup),
            setup: setup.clone(),
            scene: Mutex::new(SceneJson {
                version: 0,
                robot: setup.model.to_string(),
                tracker: PoseJson::from_iso(&setup.base_from_tracker),
                head_from_ellipsoid,
                head_radii_mm,
                head_mesh,
                coil_radius_mm: file.coil.radius_m * 1e3,
                coil_thickness_mm: file.coil.thickness_m * 1e3,
                coil_outline_mm: file.coil.loaded_casing.as_deref().map(outline_json),
            }),
            store: Mutex::new(Store {
                teach_window: Vec::new(),
                status,
                events: VecDeque::new(),
                history: VecDeque::new(),
                config: file.clone(),
            }),
            status_tx,
            started: std::time::Instant::now(),
            streams: Mutex::new(Vec::new()),
        })
    }

    /// The fixed scene.
    pub fn scene(&self) -> SceneJson {
        self.scene
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Places the scene of an experiment's run: the coil robot, the calibrated tracker, the
    /// models; its version moves on, so a page fetches it again.
    pub fn set_scene(&self, robot: String, loop_cfg: &LoopConfig) {
        let mut s = self.scene.lock().unwrap_or_else(PoisonError::into_inner);
        let (head_from_ellipsoid, head_radii_mm, head_mesh) = head_json(&loop_cfg.head);
        *s = SceneJson {
            version: s.version + 1,
            robot,
            tracker: PoseJson::from_iso(&loop_cfg.base_from_tracker),
            head_from_ellipsoid,
            head_radii_mm,
            head_mesh,
            coil_radius_mm: loop_cfg.coil.radius * 1e3,
            coil_thickness_mm: loop_cfg.coil.thickness * 1e3,
            coil_outline_mm: loop_cfg.coil.casing.as_deref().map(outline_json),
        };
    }

    /// Publishes a phase that is not a loop's (starting the simulators, calibrating): the mode
    /// `starting` with `what` as its reason.
    pub fn publish_phase(&self, what: &str) {
        let mut status = StatusJson::starting();
        status.reason = Some(what.to_string());
        status.reason_text = Some(what.to_string());
        status.mode_text = format!("starting: {what}");
        status.scene_version = self.scene().version;
        self.publish(status, None, None);
    }

    fn store(&self) -> MutexGuard<'_, Store> {
        self.store.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The newest status.
    pub fn status(&self) -> StatusJson {
        self.store().status.clone()
    }

    /// The events kept, oldest first.
    pub fn events(&self) -> Vec<EventJson> {
        self.store().events.iter().cloned().collect()
    }

    /// The plot's points: (t s, deviation mm, head speed mm/s).
    pub fn history(&self) -> Vec<[f64; 3]> {
        self.store().history.iter().copied().collect()
    }

    /// The running configuration.
    pub fn config(&self) -> Config {
        self.store().config.clone()
    }

    /// The loop's head estimates and joints of its last cycles, oldest first (for teaching).
    pub fn teach_window(&self) -> Vec<(Isometry3<f64>, [f64; 6])> {
        self.store().teach_window.clone()
    }

    /// Replaces the running configuration (after the loop was given its change).
    pub fn set_config(&self, config: Config) {
        self.store().config = config;
    }

    /// A receiver of each status as JSON text.
    pub fn subscribe(&self) -> watch::Receiver<Published> {
        self.status_tx.subscribe()
    }

    /// Registers a stream; it stores the version of each status it has sent.
    pub fn register_stream(&self) -> Arc<AtomicU64> {
        let sent = Arc::new(AtomicU64::new(0));
        self.streams
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(Arc::downgrade(&sent));
        sent
    }

    /// Waits, up to `max`, until every open stream has sent the newest status (the session's
    /// last word: stopped, calibrated), so the pages show it before the process ends.
    pub fn linger(&self, max: std::time::Duration) {
        let newest = self.status_tx.borrow().version;
        let until = std::time::Instant::now() + max;
        loop {
            let behind = {
                let mut streams = self.streams.lock().unwrap_or_else(PoisonError::into_inner);
                streams.retain(|w| w.strong_count() > 0);
                streams
                    .iter()
                    .filter_map(std::sync::Weak::upgrade)
                    .any(|s| s.load(Ordering::Acquire) < newest)
            };
            if !behind || std::time::Instant::now() >= until {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
    }

    fn publish(
        &self,
        status: StatusJson,
        point: Option<[f64; 3]>,
        window: Option<Vec<(Isometry3<f64>, [f64; 6])>>,
    ) {
        let text: Arc<str> = serde_json::to_string(&status).unwrap_or_default().into();
        {
            let mut s = self.store();
            if let Some(w) = window {
                s.teach_window = w;
            }
            if let Some(p) = point {
                s.history.push_back(p);
                while s.history.front().is_some_and(|q| p[0] - q[0] > HISTORY_S) {
                    s.history.pop_front();
                }
            }
            s.status = status;
        }
        self.status_tx.send_modify(|p| {
            p.version += 1;
            p.text = text;
        });
    }

    /// Publishes a calibration collection's progress as the status, with an event when `event`
    /// says what happened.
    pub fn publish_calibration(&self, c: CalibrationJson, event: Option<String>) {
        let mut status = StatusJson::starting();
        let (mode, reason) = match c.state {
            "waiting" => (
                "waiting",
                format!(
                    "{} calibration poses planned: press Start (the arm will move)",
                    c.planned
                ),
            ),
            "collecting" => (
                "calibrating",
                format!("pose {} of {}", c.done + 1, c.planned),
            ),
            other => (other, c.message.clone().unwrap_or_default()),
        };
        status.mode = mode.into();
        status.mode_text = format!("{mode}: {reason}");
        status.reason_text = Some(reason.clone());
        status.reason = Some(reason);
        status.running = matches!(c.state, "waiting" | "collecting");
        status.calibration = Some(c);
        if let Some(text) = event {
            // No loop clock here: seconds since the console started.
            self.push_event(EventJson {
                t: self.started.elapsed().as_secs_f64(),
                kind: "calibration",
                reason: Some(text.clone()),
                text,
            });
        }
        self.publish(status, None, None);
    }

    /// Publishes a navigation task's progress as the status, with an event when `event` says
    /// what happened.
    pub fn publish_navigation(&self, n: NavigationJson, event: Option<String>) {
        let mut status = StatusJson::starting();
        let reason = match n.state {
            "waiting" => format!("{}: press Start when the patient is ready", n.task),
            "running" => n.step.clone(),
            _ => n.result.first().cloned().unwrap_or_default(),
        };
        status.mode = n.state.into();
        status.mode_text = format!("{}: {reason}", n.state);
        status.reason_text = Some(reason.clone());
        status.reason = Some(reason);
        status.running = matches!(n.state, "waiting" | "running");
        status.navigation = Some(n);
        if let Some(text) = event {
            self.push_event(EventJson {
                t: self.started.elapsed().as_secs_f64(),
                kind: "navigation",
                reason: Some(text.clone()),
                text,
            });
        }
        self.publish(status, None, None);
    }

    fn push_event(&self, e: EventJson) {
        let mut s = self.store();
        if s.events.len() == EVENTS_KEPT {
            s.events.pop_front();
        }
        s.events.push_back(e);
    }
}

/// The frames the observer computes the scene with.
#[derive(Debug, Clone, Copy)]
pub struct Frames {
    arm: Arm,
    flange_from_coil: Isometry3<f64>,
    coil_from_head: Isometry3<f64>,
    /// The head marker's frame to the image's (its MRI's slices).
    image_from_head: Isometry3<f64>,
}

impl Frames {
    /// The frames of a loop configuration on `arm` (an experiment's run).
    pub fn of_loop(arm: Arm, loop_cfg: &LoopConfig) -> Self {
        Self {
            arm,
            flange_from_coil: loop_cfg.flange_from_coil,
            coil_from_head: loop_cfg.head_from_coil_goal.inverse(),
            image_from_head: Isometry3::identity(),
        }
    }

    /// The session's frames; a missing coil mounting is named.
    pub fn of(setup: &Setup) -> Result<Self, mocomp_app::AppError> {
        let flange_from_coil = setup.file.flange_from_coil()?;
        // The goal may not be taught yet (a real head): the view then shows the head at the
        // coil's goal frame.
        let head_from_coil = setup
            .file
            .head_from_coil()
            .unwrap_or_else(|_| Isometry3::identity());
        Ok(Self {
            arm: setup.arm,
            flange_from_coil,
            coil_from_head: head_from_coil.inverse(),
            image_from_head: setup.file.head.head_from_image.iso().inverse(),
        })
    }
}

/// Tells the console what the loop does (on the logger thread).
#[derive(Debug)]
pub struct ConsoleObserver {
    shared: Arc<Shared>,
    frames: Frames,
    /// The controller it watches, when it says (the experiment's).
    controller: Option<&'static str>,
    /// (t, tracker_from_head, joints) of the last [`TEACH_WINDOW_S`].
    window: VecDeque<(f64, Isometry3<f64>, [f64; 6])>,
    last: Option<StatusJson>,
    /// Loop time of the last published status, and cycles since.
    published_t: f64,
    cycles: u64,
    /// The session's gate and pulses, from its notes.
    session: Option<SessionNow>,
}

impl ConsoleObserver {
    /// An observer feeding `shared`.
    pub fn new(shared: Arc<Shared>, frames: Frames) -> Self {
        Self {
            shared,
            frames,
            controller: None,
            window: VecDeque::new(),
            last: None,
            published_t: f64::NEG_INFINITY,
            cycles: 0,
            session: None,
        }
    }

    /// The same, naming the controller it watches.
    pub fn of_controller(mut self, name: &'static str) -> Self {
        self.controller = Some(name);
        self
    }

    fn status_of(&self, r: &CycleRecord, age_s: f64, rate_hz: f64) -> StatusJson {
        let (mode, rule) = match r.mode {
            Mode::Tracking => ("tracking", None),
            Mode::Approaching => ("approaching", None),
            Mode::Holding(x) => ("holding", Some(x)),
            Mode::Faulted(x) => ("faulted", Some(x)),
            Mode::Retreating(x) => ("retreating", Some(x)),
        };
        let (reason, reason_text) = (
            rule.as_ref().map(rule_code),
            rule.as_ref().map(ToString::to_string),
        );
        let now_ms = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
        let measured = r.q_actual.iter().all(|q| q.is_finite());
        let links_mm = if measured {
            self.frames
                .arm
                .link_frames(&r.q_actual)
                .iter()
                .map(|f| (f.translation.vector * 1e3).into())
                .collect()
        } else {
            Vec::new()
        };
        let coil = measured.then(|| {
            PoseJson::from_iso(
                &(self.frames.arm.fk_flange(&r.q_actual) * self.frames.flange_from_coil),
            )
        });
        let goal_coil = r.goal.map(|g| g * self.frames.flange_from_coil);
        StatusJson {
            t: r.t,
            mode: mode.into(),
            reason,
            reason_text,
            mode_text: mode_name(&r.mode),
            rate_hz,
            horizon_ms: r.horizon_s * 1e3,
            sample_age_ms: r.sample_age_s * 1e3,
            command_delay_ms: r.command_delay_s * 1e3,
            deviation_mm: r.deviation.0 * 1e3,
            deviation_deg: r.deviation.1.to_degrees(),
            head_speed_mm_s: r.head_speed.0 * 1e3,
            head_speed_deg_s: r.head_speed.1.to_degrees(),
            clearance_mm: r.clearance_m * 1e3,
            standoff_mm: r.standoff_m * 1e3,
            force_n: r.contact_force_n.is_finite().then_some(r.contact_force_n),
            dose_pct: r.dose_pct.is_finite().then_some(r.dose_pct),
            dose_v_per_m: r.dose_v_per_m.is_finite().then_some(r.dose_v_per_m),
            operator_hold: self.shared.controls.hold(),
            freedrive: self.shared.controls.freedrive(),
            running: true,
            cycle_unix_ms: now_ms - age_s.max(0.0) * 1e3,
            camera: self
                .shared
                .controls
                .vision()
                .and_then(|v| v.preview())
                .map(|p| CameraJson::of(&p)),
            calibration: None,
            navigation: None,
            controller: self.controller,
            scene_version: self.shared.scene().version,
            scene: SceneNow {
                links_mm,
                coil,
                goal: goal_coil.map(|g| PoseJson::from_iso(&g)),
                head: goal_coil.map(|g| PoseJson::from_iso(&(g * self.frames.coil_from_head))),
                image: Some(ImageNow {
                    coil: r.coil_now.map(|c| {
                        crate::mri::coil_in_image("coil", &(self.frames.image_from_head * c))
                    }),
                    goal: crate::mri::coil_in_image(
                        "goal",
                        &(self.frames.image_from_head * r.head_from_coil_goal),
                    ),
                }),
            },
            session: self.session.clone(),
        }
    }
}

impl Observer for ConsoleObserver {
    fn event(&mut self, t: f64, event: &Event) {
        self.shared.push_event(EventJson::new(t, event));
    }

    fn status(&mut self, _: &Status) {}

    fn note(&mut self, note: &Note) {
        // Only the gate and the pulses show (other notes are in the events).
        if !matches!(note, Note::Gate(..) | Note::Pulse(..)) {
            return;
        }
        let s = self.session.get_or_insert(SessionNow {
            gate_open: false,
            gate_why: String::new(),
            pulses: 0,
            pulses_off_target: 0,
            last_pulse: None,
        });
        match note {
            Note::Gate(_, GateEvent::Opened, _) => {
                s.gate_open = true;
                s.gate_why.clear();
            }
            Note::Gate(_, GateEvent::Shut(why), _) => {
                s.gate_open = false;
                s.gate_why = shut_reason(why);
            }
            Note::Pulse(p, _) => {
                let open = p.gate == GateState::Open;
                s.pulses += 1;
                s.pulses_off_target += u64::from(!open);
                s.last_pulse = Some((
                    p.position_error_m * 1e3,
                    p.angle_error_rad.to_degrees(),
                    open,
                ));
            }
            _ => {}
        }
    }

    fn session(&mut self, t: f64, text: &str) {
        self.shared.push_event(EventJson {
            t,
            kind: "session",
            reason: None,
            text: text.to_string(),
        });
    }

    fn cycle(&mut self, r: &CycleRecord, age_s: f64) {
        self.cycles += 1;
        match r.head_now {
            Some(h) if r.q_actual.iter().all(|q| q.is_finite()) => {
                self.window.push_back((r.t, h, r.q_actual));
                while self
                    .window
                    .front()
                    .is_some_and(|w| r.t - w.0 > TEACH_WINDOW_S)
                {
                    self.window.pop_front();
                }
            }
            // The head or the arm unknown: nothing to teach from.
            _ => self.window.clear(),
        }
        let dt = r.t - self.published_t;
        if dt < 1.0 / STATUS_RATE_HZ {
            return;
        }
        // Cycles since the last status, this one included, over the loop time between them.
        let rate = if dt.is_finite() {
            self.cycles as f64 / dt
        } else {
            0.0
        };
        let status = self.status_of(r, age_s, rate);
        let point = [r.t, status.deviation_mm, status.head_speed_mm_s];
        self.last = Some(status.clone());
        let window = self.window.iter().map(|(_, h, q)| (*h, *q)).collect();
        self.shared.publish(status, Some(point), Some(window));
        self.published_t = r.t;
        self.cycles = 0;
    }
}

impl Drop for ConsoleObserver {
    /// The loop has ended (its logger drops the observer): the page shows it.
    fn drop(&mut self) {
        let mut last = self.last.take().unwrap_or_else(StatusJson::starting);
        last.running = false;
        last.mode = "stopped".into();
        last.mode_text = "stopped".into();
        last.reason = None;
        last.rate_hz = 0.0;
        self.shared.publish(last, None, Some(Vec::new()));
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Point3;
    use mocomp_head::{Head, MeshHead};

    #[test]
    fn the_page_gets_a_scalp_as_its_triangles_and_an_ellipsoid_as_its_axes() {
        let (_, radii, mesh) = head_json(&HeadModel::adult());
        assert_eq!(radii, [75.0, 95.0, 110.0]);
        assert!(mesh.is_none());
        // An octahedron of radius 100 mm, wound outward.
        let r = 0.1;
        let vertices = vec![
            Point3::new(r, 0.0, 0.0),
            Point3::new(-r, 0.0, 0.0),
            Point3::new(0.0, r, 0.0),
            Point3::new(0.0, -r, 0.0),
            Point3::new(0.0, 0.0, r),
            Point3::new(0.0, 0.0, -r),
        ];
        let mut triangles = Vec::new();
        for (a, sa) in [(0u32, 1.0), (1, -1.0)] {
            for (b, sb) in [(2u32, 1.0), (3, -1.0)] {
                for (c, sc) in [(4u32, 1.0), (5, -1.0)] {
                    triangles.push(if sa * sb * sc > 0.0 {
                        [a, b, c]
                    } else {
                        [a, c, b]
                    });
                }
            }
        }
        let head = MeshHead::new(
            Mesh {
                vertices,
                triangles,
            },
            "octahedron",
        )
        .unwrap();
        let (_, _, mesh) = head_json(&HeadModel::new(Head::Mesh(Arc::new(head))));
        let mesh = mesh.unwrap();
        assert_eq!((mesh.vertices_mm.len(), mesh.triangles.len()), (6, 8));
        for v in &mesh.vertices_mm {
            let n = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            assert!((n - 100.0).abs() < 0.01, "{v:?}");
        }
    }

    #[test]
    fn the_page_gets_a_casing_as_its_outline_at_its_face_in_millimetres() {
        // An octagonal prism 120 mm across, 15 mm thick, its face 1 mm behind the origin.
        let mut points = Vec::new();
        for k in 0..8 {
            let a = std::f64::consts::FRAC_PI_4 * k as f64;
            for z in [-0.016, -0.001] {
                points.push(Point3::new(0.06 * a.cos(), 0.06 * a.sin(), z));
            }
        }
        let casing = mocomp_head::casing::Casing::new(&points, "prism").unwrap();
        let outline = outline_json(&casing);
        assert_eq!(outline.len(), 8);
        for p in &outline {
            assert!(
                (p[0].hypot(p[1]) - 60.0).abs() < 0.1 && p[2] == -1.0,
                "{p:?}"
            );
        }
    }
}
