//! A registration rehearsed in the built-in world (`mocomp register --simulate`): the simulated
//! tracker serves the head marker (moving as `[tracker.simulated.motion]` says) and a pointer on
//! one OpenIGTLink connection, the pointer in the hand of a simulated operator
//! (`[tracker.simulated.operator]`, [`mocomp_sim::operator`]) who does what the registration
//! asks: pivots the pointer, touches the landmarks, sweeps the scalp. The image lies on the head
//! marker where `[tracker.simulated] head_from_image` says (the truth the registration is judged
//! against), and the operator touches the patient's skin, not the head model.
//!
//! [`Rehearsal::start`] serves it in real time for the live command; [`rehearse_offline`] steps
//! the same operator, tracker noise and registration procedure in one thread as fast as they go,
//! for seeded trials.

use crate::config::Setup;
use crate::registration::register::{ImageScalp, image_landmarks_all};
use crate::{AppError, Context};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_nav::{Outcome, Procedure, Prompt, Scalp, Settings, Target};
use mocomp_sim::operator::{Ask, Operator, OperatorConfig, PointerAt};
use mocomp_sim::{TrackedMarker, TrackerModel, TrackerServer, TrackerSim};
use std::sync::{Arc, Mutex};

/// The simulated pointer's device.
pub const POINTER_DEVICE: &str = "StylusToTracker";
/// Its tip in its marker's frame, mm: a 16 cm stylus, the tip a little off its axis.
pub const TIP_IN_MARKER_MM: [f64; 3] = [2.5, -4.0, 161.0];

/// What the operator is asked, for a prompt of the registration.
pub fn ask_for(p: &Prompt) -> Ask {
    match p {
        Prompt::Touch(n) => Ask::Touch(n.clone()),
        Prompt::TakeAway(n) => Ask::TakeAway(n.clone()),
        Prompt::Sweep { region, .. } => Ask::Sweep(region.clone()),
        Prompt::Done => Ask::Rest,
    }
}

/// The true place of the image on the head marker in the simulated world.
pub fn true_head_from_image(setup: &Setup) -> Isometry3<f64> {
    setup
        .file
        .tracker
        .simulated
        .head_from_image
        .as_ref()
        .map_or_else(|| setup.file.head.head_from_image.iso(), |p| p.iso())
}

/// The operator of `setup`'s simulated world, its seed replaced by `seed` when given.
pub fn operator(setup: &Setup, seed: Option<u64>) -> Result<Operator, AppError> {
    let scalp = ImageScalp::of(setup)?;
    let (head, image_from_head) = scalp.head();
    let mut config: OperatorConfig = setup.file.tracker.simulated.operator.clone();
    if let Some(s) = seed {
        config.seed = s;
    }
    let marks: Vec<(String, Point3<f64>)> = image_landmarks_all(setup)
        .into_iter()
        .map(|l| (l.name, l.point))
        .collect();
    Ok(Operator::new(
        config,
        head.shape().clone(),
        image_from_head,
        &marks,
        Vector3::from(TIP_IN_MARKER_MM) / 1000.0,
    ))
}

/// The registration's true error at each target: how far the point it puts at a target (image
/// frame) truly lies from it, m.
pub fn true_errors(
    targets: &[Target],
    found_image_from_marker: &Isometry3<f64>,
    true_image_from_marker: &Isometry3<f64>,
) -> Vec<(String, f64)> {
    targets
        .iter()
        .map(|t| {
            let at = true_image_from_marker * (found_image_from_marker.inverse() * t.point);
            (t.name.clone(), (at - t.point).norm())
        })
        .collect()
}

/// The simulated tracker serving the head marker and the operator's pointer.
#[derive(Debug)]
pub struct Rehearsal {
    server: TrackerServer,
    ask: Arc<Mutex<Ask>>,
    truth: Isometry3<f64>,
}

impl Rehearsal {
    /// Serves `setup`'s simulated world with its operator (seeded by `seed` when given) on
    /// `[tracker.simulated] serve`.
    pub fn start(setup: &Setup, seed: Option<u64>) -> Result<Self, AppError> {
        let file = &setup.file;
        let s = &file.tracker.simulated;
        let head_from_image = true_head_from_image(setup);
        let head_at = crate::world::simulated_head(setup);
        let head_at_too = head_at.clone();
        let ask = Arc::new(Mutex::new(Ask::Rest));
        let asked = Arc::clone(&ask);
        let mut op = operator(setup, seed)?;
        let mut model: TrackerModel = s.model;
        model.seed = model.seed.wrapping_add(seed.unwrap_or(0));
        let markers = vec![
            // The head first: a pointer's frame pairs with the head's of the same instant.
            TrackedMarker {
                device: file.tracker.device.clone(),
                truth: Box::new(move |t| Some(head_at(t))),
            },
            TrackedMarker {
                device: POINTER_DEVICE.into(),
                truth: Box::new(move |t| {
                    let now = asked.lock().map(|a| a.clone()).unwrap_or_default();
                    Some(match op.at(t, &now) {
                        PointerAt::Image(p) => head_at_too(t) * head_from_image * p,
                        PointerAt::Tracker(p) => p,
                    })
                }),
            },
        ];
        let server = TrackerServer::start(&s.serve, model, markers)
            .what(|| format!("tracker.simulated.serve {}: the simulated tracker", s.serve))?;
        Ok(Self {
            server,
            ask,
            truth: head_from_image.inverse(),
        })
    }

    /// Where it serves.
    pub fn addr(&self) -> String {
        self.server.addr().to_string()
    }

    /// Tells the operator what to do.
    pub fn ask(&self, a: Ask) {
        if let Ok(mut now) = self.ask.lock() {
            *now = a;
        }
    }

    /// The truth: the head marker's frame to the image's.
    pub fn image_from_marker(&self) -> Isometry3<f64> {
        self.truth
    }
}

/// A world for an offline rehearsal: the registration's scalp and landmarks, the operator, the
/// truth, the head's motion and the tracker's noise.
pub struct OfflineWorld<'a> {
    /// The head model the registration fits to (image frame) and its cuts.
    pub scalp: Scalp<'a>,
    /// The image's landmarks as the registration is given them.
    pub image: Vec<mocomp_nav::Landmark>,
    /// The procedure's settings.
    pub settings: Settings,
    /// The operator.
    pub operator: Operator,
    /// The truth: the head marker's frame to the image's.
    pub image_from_marker: Isometry3<f64>,
    /// The head marker in the tracker's view at a time.
    pub tracker_from_head: &'a dyn Fn(f64) -> Isometry3<f64>,
    /// The tracker.
    pub tracker: TrackerModel,
    /// The pointer's tip in its marker's frame as calibrated (the truth is
    /// [`TIP_IN_MARKER_MM`]), m.
    pub tip_in_marker: Vector3<f64>,
    /// Give up after this long, s.
    pub max_s: f64,
}

impl std::fmt::Debug for OfflineWorld<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OfflineWorld").finish_non_exhaustive()
    }
}

/// An offline rehearsal's result.
#[derive(Debug, Clone)]
pub struct Rehearsed {
    /// The procedure's outcome.
    pub outcome: Outcome,
    /// The registration's true error at each target, m (none without a registration).
    pub true_errors: Vec<(String, f64)>,
}

/// Steps `world` until the procedure is done (or `max_s`): the operator does what it is asked,
/// the tracker adds its noise to both markers, the tip goes to the procedure in the head
/// marker's frame.
pub fn rehearse_offline(world: OfflineWorld<'_>) -> Result<Rehearsed, AppError> {
    let OfflineWorld {
        scalp,
        image,
        settings,
        mut operator,
        image_from_marker,
        tracker_from_head,
        tracker,
        tip_in_marker,
        max_s,
    } = world;
    let targets = settings.targets.clone();
    let mut procedure = Procedure::new(scalp, &image, settings)
        .map_err(|e| AppError::Config(format!("head.landmarks: {e}")))?;
    let head_from_image = image_from_marker.inverse();
    let mut sim = TrackerSim::new(tracker, 2);
    let mut ask = ask_for(&procedure.prompt());
    let dt = 1.0 / tracker.rate_hz;
    let mut t = 0.0;
    let mut head: Option<Isometry3<f64>> = None;
    while !procedure.done() && t < max_s {
        t += dt;
        // Each pointer sample with the head marker's of the same instant, its tip in the head
        // marker's frame (NaN when either was lost).
        let mut tips: Vec<(f64, Point3<f64>)> = Vec::new();
        let asked = ask.clone();
        sim.step(
            t,
            &mut |m, at| {
                let h = tracker_from_head(at);
                Some(if m == 0 {
                    h
                } else {
                    match operator.at(at, &asked) {
                        PointerAt::Image(p) => h * head_from_image * p,
                        PointerAt::Tracker(p) => p,
                    }
                })
            },
            &mut |o| {
                let pose = o.valid.then_some(o.tracker_from_marker);
                if o.marker == 0 {
                    head = pose;
                    return;
                }
                let tip = match (pose, head) {
                    (Some(p), Some(h)) => h.inverse() * (p * Point3::from(tip_in_marker)),
                    _ => Point3::new(f64::NAN, f64::NAN, f64::NAN),
                };
                tips.push((o.acquired_s, tip));
            },
        );
        for (at, tip) in tips {
            procedure.feed(at, &tip);
            ask = ask_for(&procedure.prompt());
        }
    }
    let outcome = procedure.finish();
    let true_errors = match &outcome.registration {
        Ok(r) => true_errors(&targets, &r.image_from_marker, &image_from_marker),
        Err(_) => Vec::new(),
    };
    Ok(Rehearsed {
        outcome,
        true_errors,
    })
}
