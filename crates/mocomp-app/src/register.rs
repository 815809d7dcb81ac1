//! Patient-to-image registration live (`mocomp register`): the calibrated pointer's tip in the
//! head marker's frame from the two OpenIGTLink streams (pointer and head marker), fed to the
//! capture ([`mocomp_nav::capture`]) that tells the operator's touches and sweep apart, then the
//! registration ([`mocomp_nav::register`]) against the configuration's scalp and landmarks; and
//! the check that the marker has not moved on the head since (`mocomp register check`).

use crate::AppError;
use crate::config::Setup;
use crate::listen::{ListenOptions, listen_devices};
use crate::pointer::Pointer;
use crate::registration_file::{Record, RegistrationFile};
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_head::Reframed;
use mocomp_igtl::message::F32_RIGID_TOLERANCE;
use mocomp_nav::{Capture, CaptureOptions, Captured, IcpOptions, Landmark, Registration, Step};
use std::ops::ControlFlow;
use std::time::Duration;

/// A pointer pose pairs with the head marker's when their timestamps are this close, s (PLUS
/// stamps both of one frame alike).
const PAIR_WITHIN_S: f64 = 0.02;

/// The least distance between a landmark's touch now and at registration that counts as the
/// marker having moved on the head, m.
pub const MOVED_BEYOND_M: f64 = 3e-3;

/// Two touches of one landmark, each off by the localisation error (FLE, RMS in 3-D), lie
/// within this many FLEs of each other 95 % of the time: their difference has √2 the error,
/// and a 3-D distance's 95th percentile is √(7.81/3) of its RMS.
const RETOUCH_95: f64 = 2.28;

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

/// Feeds `each` the pointer's tip in the head marker's frame (m; NaN when either marker is not
/// seen validly or the two are not of one frame) until it says break.
pub fn tips_in_head(
    streams: &Streams,
    pointer: &Pointer,
    each: &mut dyn FnMut(Point3<f64>) -> ControlFlow<()>,
) -> Result<(), AppError> {
    let o = ListenOptions {
        addr: streams.addr.clone(),
        device: pointer.device.clone(),
        count: None,
        timeout: streams.timeout,
        stt_tdata: false,
    };
    let tip = pointer.tip();
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
            Ok(each(at))
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

/// What a registration produced.
#[derive(Debug, Clone)]
pub struct Registered {
    /// The registration.
    pub registration: Registration,
    /// Its file, written.
    pub file: RegistrationFile,
    /// Swept points left out as too far from the scalp.
    pub too_far: usize,
}

/// Registers live: the operator touches `names` in turn and sweeps `sweep_points` over the
/// scalp; `say` is told each step, `follow` the capture whenever it moved on. The registration
/// is checked against the configuration's scalp and `[head.landmarks]`.
pub fn register_live(
    setup: &Setup,
    streams: &Streams,
    pointer: &Pointer,
    names: &[&str],
    sweep_points: usize,
    say: &mut dyn FnMut(&str),
    follow: &mut dyn FnMut(&Capture),
) -> Result<Registered, AppError> {
    let image = image_landmarks(setup, names)?;
    let options = CaptureOptions {
        sweep_points,
        ..CaptureOptions::default()
    };
    let mut capture = Capture::new(names, options);
    let mut last_step = None;
    let mut last_swept = 0;
    follow(&capture);
    tips_in_head(streams, pointer, &mut |tip| {
        let got = capture.feed(&tip);
        if let Some(Captured::Landmark(l, spread)) = &got {
            say(&format!(
                "{}: touched (the burst within {:.2} mm)",
                l.name,
                spread * 1e3
            ));
        }
        let step = capture.step();
        if last_step.as_ref() != Some(&step) {
            match &step {
                Step::Touch(n) => say(&format!("touch the {n} with the pointer and hold still")),
                Step::TakeAway(n) => say(&format!("take the pointer off the {n}")),
                Step::Sweep(0, n) => say(&format!("sweep the pointer over the scalp ({n} points)")),
                Step::Sweep(..) | Step::Done => {}
            }
            last_step = Some(step.clone());
            follow(&capture);
        } else if got.is_some() || capture.sweep().len() != last_swept {
            follow(&capture);
        }
        last_swept = capture.sweep().len();
        if step == Step::Done {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })?;
    compute(setup, &image, capture.landmarks(), capture.sweep())
}

/// The registration of the `touched` landmarks and `swept` points against the configuration's
/// scalp and its `image` landmarks.
pub fn compute(
    setup: &Setup,
    image: &[Landmark],
    touched: &[Landmark],
    swept: &[Point3<f64>],
) -> Result<Registered, AppError> {
    let head = crate::navigation::scan_head(setup)?;
    let scalp = Reframed::new(
        head.shape(),
        setup.file.head.head_from_image.iso().inverse(),
    );
    let registration = mocomp_nav::register(&scalp, image, touched, swept, &IcpOptions::default())
        .map_err(|e| AppError::Refused(format!("registration: {e}")))?;
    let too_far = registration.surface.as_ref().map_or(0, |s| s.too_far);
    let file = RegistrationFile {
        registration: Record::new(&registration, image, touched, &crate::targets::now()),
        overrides: Vec::new(),
    };
    Ok(Registered {
        registration,
        file,
        too_far,
    })
}

/// `[head.landmarks]` named `names` (image frame, m).
pub fn image_landmarks(setup: &Setup, names: &[&str]) -> Result<Vec<Landmark>, AppError> {
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
    /// Beyond this it has moved: [`MOVED_BEYOND_M`], or more where the registration's own
    /// touches were less certain, m.
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
    let Some((path, record)) = &setup.file.head.registered else {
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
    say(&format!("touch the {name} with the pointer and hold still"));
    let mut capture = Capture::new(
        &[name],
        CaptureOptions {
            sweep_points: 0,
            ..CaptureOptions::default()
        },
    );
    let mut now = None;
    tips_in_head(streams, pointer, &mut |tip| {
        if let Some(Captured::Landmark(l, _)) = capture.feed(&tip) {
            now = Some(l.point);
            return ControlFlow::Break(());
        }
        ControlFlow::Continue(())
    })?;
    let now = now.ok_or_else(|| AppError::Refused(format!("{name}: no touch")))?;
    let moved_m = (now - was).norm();
    let limit_m = MOVED_BEYOND_M.max(RETOUCH_95 * record.fle_mm / 1000.0);
    Ok(Checked {
        name: name.to_string(),
        moved_m,
        limit_m,
        moved: moved_m > limit_m,
    })
}
