//! Patient-to-image registration live (`mocomp register`): the calibrated pointer's tip in the
//! head marker's frame from the two OpenIGTLink streams (pointer and head marker), fed to the
//! registration procedure ([`mocomp_nav::procedure`]: the landmarks touched, checked against each
//! other, the scalp swept until the error bound at the targets is enough) against the
//! configuration's scalp and landmarks; the outcome written only when it passed its checks; and
//! the check that the marker has not moved on the head since (`mocomp register check`).

use crate::AppError;
use crate::config::Setup;
use crate::config::registration_file::{Record, RegistrationFile};
use crate::listen::{ListenOptions, listen_devices};
use crate::registration::pointer::Pointer;
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_head::{Reframed, ScanCut};
use mocomp_igtl::message::F32_RIGID_TOLERANCE;
use mocomp_nav::{
    CaptureOptions, Captured, Landmark, LandmarkCapture, Outcome, Procedure, Prompt, Scalp,
};
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

/// A pointer pose pairs with the head marker's when their timestamps are this close, s (PLUS
/// stamps both of one frame alike).
const PAIR_WITHIN_S: f64 = 0.02;

/// The least distance between a landmark's touch now and at registration that counts as the
/// marker having moved on the head, m.
pub const MOVED_BEYOND_M: f64 = 3e-3;

/// Where the streams are.
#[derive(Debug, Clone)]
pub struct Streams {
    /// The OpenIGTLink server.
    pub addr: String,
    /// The head marker's device.
    pub head_device: String,
    /// Give up when nothing arrives for this long.
    pub timeout: Duration,
}

/// Feeds `each` the time (the pointer's timestamp, else its arrival, s) and the pointer's tip in
/// the head marker's frame (m; NaN when either marker is not seen validly or the two are not of
/// one frame) until it says break.
pub fn tips_in_head(
    streams: &Streams,
    pointer: &Pointer,
    each: &mut dyn FnMut(f64, Point3<f64>) -> ControlFlow<()>,
) -> Result<(), AppError> {
    let o = ListenOptions {
        addr: streams.addr.clone(),
        device: pointer.device.clone(),
        count: None,
        timeout: streams.timeout,
        stt_tdata: false,
    };
    let tip = pointer.tip();
    let start = Instant::now();
    let mut head: Option<(Option<f64>, Option<Isometry3<f64>>)> = None;
    let pose = |h: &crate::listen::Heard| {
        h.valid
            .then(|| iso_from_matrix_mm(&h.matrix_mm, F32_RIGID_TOLERANCE).ok())
            .flatten()
    };
    listen_devices(
        &o,
        &[pointer.device.as_str(), streams.head_device.as_str()],
        &mut |index, h| {
            if index == 1 {
                head = Some((h.t, pose(h)));
                return Ok(ControlFlow::Continue(()));
            }
            let lost = Point3::new(f64::NAN, f64::NAN, f64::NAN);
            let at = match (pose(h), head) {
                (Some(tracker_from_pointer), Some((t_head, Some(tracker_from_head))))
                    if paired(h.t, t_head) =>
                {
                    tracker_from_head.inverse() * (tracker_from_pointer * Point3::from(tip))
                }
                _ => lost,
            };
            let t = h.t.unwrap_or_else(|| start.elapsed().as_secs_f64());
            Ok(each(t, at))
        },
    )?;
    Ok(())
}

/// The two poses are of one frame: their timestamps agree, or neither has one (the latest head
/// pose is then the pointer's).
fn paired(pointer: Option<f64>, head: Option<f64>) -> bool {
    match (pointer, head) {
        (Some(a), Some(b)) => (a - b).abs() <= PAIR_WITHIN_S,
        (None, None) => true,
        _ => false,
    }
}

/// The configuration's scalp in the image's frame, and where the scan cut it (image frame).
pub struct ImageScalp {
    head: mocomp_control::HeadModel,
    image_from_head: Isometry3<f64>,
    cuts: Vec<ScanCut>,
}

impl std::fmt::Debug for ImageScalp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImageScalp")
            .field("cuts", &self.cuts.len())
            .finish_non_exhaustive()
    }
}

impl ImageScalp {
    /// `setup`'s head model seen in the image's frame.
    pub fn of(setup: &Setup) -> Result<Self, AppError> {
        let head = setup.file.head_model()?;
        let image_from_head = setup.file.head.head_from_image.iso().inverse();
        let cuts = head
            .scan_cuts()
            .iter()
            .map(|c| c.transformed(&image_from_head))
            .collect();
        Ok(Self {
            head,
            image_from_head,
            cuts,
        })
    }

    /// The shape in the image's frame.
    pub fn shape(&self) -> Reframed<'_> {
        Reframed::new(self.head.shape(), self.image_from_head)
    }

    /// The head model (head marker frame) and its frame in the image's.
    pub fn head(&self) -> (&mocomp_control::HeadModel, Isometry3<f64>) {
        (&self.head, self.image_from_head)
    }

    /// The scan's cuts, image frame.
    pub fn cuts(&self) -> &[ScanCut] {
        &self.cuts
    }
}

/// What a registration produced.
#[derive(Debug, Clone)]
pub struct Registered {
    /// The procedure's outcome: the registration, why it may not be used, the bounds at the
    /// targets.
    pub outcome: Outcome,
    /// Its file, when it may be used.
    pub file: Option<RegistrationFile>,
}

impl Registered {
    /// Whether it passed every check.
    pub fn usable(&self) -> bool {
        self.file.is_some()
    }
}

/// What `register` is asked for beyond the configuration.
#[derive(Debug, Clone)]
pub struct Asked {
    /// The landmarks to touch, in order.
    pub landmarks: Vec<String>,
    /// Sweep points at most.
    pub sweep_points: usize,
}

/// What the registration tells as it goes.
pub trait Follow {
    /// A line for the operator.
    fn say(&mut self, line: &str);
    /// The procedure moved on (its state).
    fn moved(&mut self, p: &Procedure<'_>);
}

/// What the operator is to do, said once when it changes.
pub fn prompt_line(p: &Prompt) -> Option<String> {
    match p {
        Prompt::Touch(n) => Some(format!("touch the {n} with the pointer and hold still")),
        Prompt::TakeAway(n) => Some(format!("take the pointer off the {n}")),
        Prompt::Sweep { taken: 0, of, .. } => Some(format!(
            "sweep the pointer over the scalp, touching it (up to {of} points; it ends when the \
             error at the targets is small enough)"
        )),
        Prompt::Sweep { .. } | Prompt::Done => None,
    }
}

/// The image's landmarks (`[head.landmarks]`), every one the configuration names.
pub fn image_landmarks_all(setup: &Setup) -> Vec<Landmark> {
    setup
        .file
        .head
        .landmarks
        .keys()
        .filter_map(|k| {
            crate::navigation::find_landmark(&setup.file.head.landmarks, k)
                .map(|p| Landmark::new(k, p))
        })
        .collect()
}

/// The image's landmarks `names` exist and lie on the configuration's scalp (within 10 mm, not on
/// a scan's cut): a configuration error, before anything starts.
pub fn check_landmarks(setup: &Setup, names: &[String]) -> Result<(), AppError> {
    let scalp = ImageScalp::of(setup)?;
    let shape = scalp.shape();
    let image = image_landmarks(setup, names)?;
    mocomp_nav::registration::on_scalp(
        &Scalp {
            shape: &shape,
            cuts: scalp.cuts(),
        },
        &image,
    )
    .map(|_| ())
    .map_err(|e| AppError::Config(format!("head.landmarks: {e}")))
}

/// Registers live: the procedure fed the tips the streams give, `follow` told of each step,
/// `ask` of each prompt (a simulated operator listens), until it is done.
pub fn register_live(
    setup: &Setup,
    streams: &Streams,
    pointer: &Pointer,
    asked: &Asked,
    follow: &mut dyn Follow,
    ask: &mut dyn FnMut(&Prompt),
) -> Result<Registered, AppError> {
    let scalp = ImageScalp::of(setup)?;
    let shape = scalp.shape();
    let image = image_landmarks(setup, &asked.landmarks)?;
    let targets = crate::registration::gate::targets(setup, None)?;
    let settings = setup.file.registration.settings(
        &asked.landmarks,
        asked.sweep_points,
        targets,
        setup.file.head.max_tre_mm,
    );
    let mut procedure = Procedure::new(
        Scalp {
            shape: &shape,
            cuts: scalp.cuts(),
        },
        &image,
        settings,
    )
    .map_err(|e| AppError::Config(format!("head.landmarks: {e}")))?;
    for l in procedure.image_landmarks() {
        if l.offset_m.abs() > 1e-3 {
            follow.say(&format!(
                "the image's {} lies {:.1} mm {} the scalp: taken on the scalp",
                l.name,
                l.offset_m.abs() * 1e3,
                if l.offset_m > 0.0 {
                    "outside"
                } else {
                    "inside"
                }
            ));
        }
    }
    let mut last = None;
    let mut announce =
        |p: &Procedure<'_>, follow: &mut dyn Follow, ask: &mut dyn FnMut(&Prompt)| {
            let prompt = p.prompt();
            if last.as_ref() != Some(&prompt) {
                let step_changed = !matches!(
                    (&last, &prompt),
                    (Some(Prompt::Sweep { .. }), Prompt::Sweep { taken, .. }) if *taken > 0
                );
                if step_changed && let Some(line) = prompt_line(&prompt) {
                    follow.say(&line);
                }
                ask(&prompt);
                follow.moved(p);
                last = Some(prompt);
            }
        };
    announce(&procedure, follow, ask);
    tips_in_head(streams, pointer, &mut |t, tip| {
        for n in procedure.feed(t, &tip) {
            follow.say(&n.to_string());
        }
        announce(&procedure, follow, ask);
        if procedure.done() {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })?;
    Ok(conclude(setup, procedure.finish()))
}

/// The outcome, with its file when it may be used.
pub fn conclude(setup: &Setup, outcome: Outcome) -> Registered {
    let file = match (&outcome.registration, outcome.refusals.is_empty()) {
        (Ok(r), true) => Some(RegistrationFile {
            registration: Record::new(
                r,
                setup.file.registration.noise,
                &crate::navigation::targets::now(),
            ),
            overrides: Vec::new(),
        }),
        _ => None,
    };
    Registered { outcome, file }
}

/// Why a registration may not be used, as one error naming every reason (none: it may).
pub fn refused(r: &Registered) -> Option<AppError> {
    match &r.outcome.registration {
        Err(e) => Some(AppError::Refused(format!("registration: {e}"))),
        Ok(_) if r.outcome.refusals.is_empty() => None,
        Ok(_) => Some(AppError::Refused(format!(
            "registration refused, not written: {}",
            r.outcome
                .refusals
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join("; ")
        ))),
    }
}

/// `[head.landmarks]` named `names` (image frame, m).
pub fn image_landmarks(setup: &Setup, names: &[String]) -> Result<Vec<Landmark>, AppError> {
    let marks = &setup.file.head.landmarks;
    names
        .iter()
        .map(|name| {
            crate::navigation::find_landmark(marks, name)
                .map(|p| Landmark::new(name, p))
                .ok_or_else(|| {
                    AppError::Config(format!(
                        "head.landmarks: no {name} (it has {})",
                        marks.keys().cloned().collect::<Vec<_>>().join(", ")
                    ))
                })
        })
        .collect()
}

/// What `register check` found at one landmark.
#[derive(Debug, Clone, PartialEq)]
pub struct Checked {
    /// The landmark.
    pub name: String,
    /// How far the touch lies from where it was touched at registration (head marker frame),
    /// m.
    pub moved_m: f64,
    /// Beyond this it has moved: [`MOVED_BEYOND_M`], or more where two touches of one landmark
    /// differ by more 5 % of the time, m.
    pub limit_m: f64,
    /// Whether it moved.
    pub moved: bool,
}

/// The operator touches `name` again: how far it now lies in the marker's frame from where the
/// registration had it.
pub fn check_live(
    setup: &Setup,
    streams: &Streams,
    pointer: &Pointer,
    name: &str,
    say: &mut dyn FnMut(&str),
) -> Result<Checked, AppError> {
    let Some((path, record)) = &setup.file.loaded.registered else {
        return Err(AppError::Config(
            "head.registration: none to check (run `mocomp register` first)".into(),
        ));
    };
    let Some(was) = record.touched(name) else {
        return Err(AppError::Config(format!(
            "{}: the registration used no {name} (it used {})",
            path.display(),
            record
                .landmarks
                .keys()
                .cloned()
                .collect::<Vec<_>>()
                .join(", ")
        )));
    };
    say(&format!(
        "touch the {name} with the pointer, hold still, then take it away"
    ));
    let mut capture = LandmarkCapture::new(name, CaptureOptions::default());
    let mut now = None;
    tips_in_head(streams, pointer, &mut |t, tip| {
        if let Some(Captured::Touched(touch)) = capture.feed(t, &tip, &|_| None) {
            now = Some(touch.landmark.point);
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    })?;
    let now = now.ok_or_else(|| AppError::Refused(format!("{name}: no touch")))?;
    let moved_m = (now - was).norm();
    // Two touches of one landmark differ along the skin by √2 of a touch's error per axis; 95 %
    // of a 2-D Gaussian's lengths lie within √χ²₂(0.95) of its σ.
    let retouch_95 = mocomp_nav::bound::chi2_quantile(2, 0.95).sqrt()
        * std::f64::consts::SQRT_2
        * record.noise.touch_sigma_mm
        / 1000.0;
    let limit_m = MOVED_BEYOND_M.max(retouch_95);
    Ok(Checked {
        name: name.to_string(),
        moved_m,
        limit_m,
        moved: moved_m > limit_m,
    })
}
