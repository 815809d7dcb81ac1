//! Navigation on the configuration's head: the image's landmarks (`[head.landmarks]`, mm at the
//! file, metres from here on), the scalp seen in the image's frame, the 10-20 positions on it,
//! and a target in the image (a point, an MNI coordinate, an EEG position) placed as a coil goal
//! in the head marker's frame, through `[head] head_from_image`.

pub mod eeg_report;
pub mod placement;
pub mod placement_report;
pub mod target_import;
pub mod target_report;
pub mod targets;

use crate::AppError;
use crate::config::Setup;
use mocomp_control::goal::{GoalError, check_goal};
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Point3};
use mocomp_head::{CoilSolid, Reframed};
use mocomp_nav::{
    CoilPlacement, CranialLandmarks, DoseAlong, DoseMap, DoseSearch, EegPosition, FieldAt, Handle,
    System,
};
use mocomp_session::Target;

use mocomp_geom::units::MM_PER_M;

/// A point given in millimetres, in metres.
pub fn point_from_mm(mm: [f64; 3]) -> Point3<f64> {
    Point3::from(mm) / MM_PER_M
}

/// A point in metres, in millimetres.
pub fn mm_from_point(p: &Point3<f64>) -> [f64; 3] {
    (p * MM_PER_M).coords.into()
}

/// `[head.landmarks]`'s nasion, inion and preauricular points (names without regard to case),
/// image frame, m.
pub fn cranial_landmarks(setup: &Setup) -> Result<CranialLandmarks, AppError> {
    let marks = &setup.file.head.landmarks;
    let get = |name: &str| {
        find_landmark(marks, name).ok_or_else(|| {
            AppError::Config(format!(
                "head.landmarks: no {name} (the 10-20 system is measured from nasion, inion, lpa \
                 and rpa, image RAS in mm){}",
                if marks.is_empty() {
                    String::new()
                } else {
                    format!(
                        "; it has {}",
                        marks.keys().cloned().collect::<Vec<_>>().join(", ")
                    )
                }
            ))
        })
    };
    Ok(CranialLandmarks {
        nasion: get("nasion")?,
        inion: get("inion")?,
        lpa: get("lpa")?,
        rpa: get("rpa")?,
    })
}

/// Other names of the cranial landmarks, as SimNIBS's and MNE's files spell them.
const ALIASES: [&[&str]; 2] = [&["nasion", "nz", "nas"], &["inion", "iz", "ini"]];

/// The landmark `name` of `marks` (mm), without regard to case or to which of its usual names
/// each uses, in metres.
pub fn find_landmark(
    marks: &std::collections::BTreeMap<String, [f64; 3]>,
    name: &str,
) -> Option<Point3<f64>> {
    let same = |a: &str, b: &str| {
        a.eq_ignore_ascii_case(b)
            || ALIASES.iter().any(|g| {
                g.iter().any(|n| n.eq_ignore_ascii_case(a))
                    && g.iter().any(|n| n.eq_ignore_ascii_case(b))
            })
    };
    marks
        .iter()
        .find(|(k, _)| same(k, name))
        .map(|(_, v)| point_from_mm(*v))
}

/// How far each configured landmark (`[head.landmarks]`, image frame) lies from the scalp of
/// `setup`'s head model, m (positive outside, negative inside), by its name in the file: a
/// landmark placed by eye off the skin moves every 10-20 position measured from it.
pub fn landmark_offsets(setup: &Setup) -> Result<Vec<(String, f64)>, AppError> {
    let head = setup.file.head_model()?;
    let head_from_image = setup.file.head.head_from_image.iso();
    Ok(setup
        .file
        .head
        .landmarks
        .iter()
        .map(|(name, mm)| {
            let p = head_from_image * point_from_mm(*mm);
            (name.clone(), head.distance(&p))
        })
        .collect())
}

/// A landmark farther than this from the scalp is worth a warning, m: the landmarks are touched
/// on the skin, and the 10-20 positions are measured along it.
pub const LANDMARK_OFF_SCALP_WARN_M: f64 = 0.002;

/// The positions of `system` on the scalp of `setup`, image frame.
pub fn eeg_positions(setup: &Setup, system: System) -> Result<Vec<EegPosition>, AppError> {
    let head = setup.file.head_model()?;
    let image_from_head = setup.file.head.head_from_image.iso().inverse();
    let scalp = Reframed::new(head.shape(), image_from_head);
    let landmarks = cranial_landmarks(setup)?;
    mocomp_nav::eeg_positions(&scalp, &landmarks, system)
        .map_err(|e| AppError::Config(format!("head.landmarks: {e}")))
}

/// What a target in the image is given as.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetSpec {
    /// A point in the image, RAS, mm.
    Image([f64; 3]),
    /// An MNI coordinate, mm, with the image_from_mni affine and the file it came from (none:
    /// the image is in MNI space).
    Mni([f64; 3], Option<(Matrix4<f64>, String)>),
    /// A 10-10 position on the scalp by name (`F3`).
    Eeg(String),
}

/// A target placed on the image: the session's target, and where and why the coil goes.
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    /// The target, `head_from_coil` and `image_from_coil`, with its source.
    pub target: Target,
    /// The coil over the scalp, image frame.
    pub placement: CoilPlacement,
    /// The target in the image, m.
    pub image_point: Point3<f64>,
    /// The coil face's distance from the scalp asked for, m (before any lift).
    pub standoff_m: f64,
    /// The whole coil's clearance from the scalp at the goal, m (exact; the loop's goal check,
    /// which passed, measures it conservatively).
    pub clearance_m: f64,
    /// Targeted by dose: what the search found (the placement is its best).
    pub dose: Option<DoseMap>,
}

/// Targeting by dose (`targets add --optimize-dose`): where to look and what to maximise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DoseTargeting {
    /// How far from the nearest scalp point the coil's centre may go, m.
    pub radius_m: f64,
    /// The direction the dose is taken along (image RAS, a gyral wall's normal); `None`: |E|.
    pub direction: Option<[f64; 3]>,
}

/// The coil placed for the largest dose at `image_point` by `t` (`[coil] model` needed): the
/// search's map, and the placement it makes.
fn place_by_dose(
    setup: &Setup,
    scalp: &dyn mocomp_head::HeadShape,
    solid: &CoilSolid,
    image_point: &Point3<f64>,
    standoff_m: f64,
    handle: &Handle,
    t: &DoseTargeting,
) -> Result<(CoilPlacement, DoseMap), AppError> {
    let Some(model) = setup.file.coil.dose_model()? else {
        return Err(AppError::Config(
            "--optimize-dose: needs coil.model (a SimNIBS .ccd file) in the configuration".into(),
        ));
    };
    let along = match t.direction {
        None => DoseAlong::Magnitude,
        Some(d) => DoseAlong::Direction(
            mocomp_geom::nalgebra::Unit::try_new(d.into(), 1e-9).ok_or_else(|| {
                AppError::Config(format!("--dose-direction {d:?}: not a direction"))
            })?,
        ),
    };
    if !(t.radius_m.is_finite() && (0.0..=0.03).contains(&t.radius_m)) {
        return Err(AppError::Config(format!(
            "--dose-radius-mm {}: 0 to 30 mm (beyond, the coil leaves the target's scalp)",
            t.radius_m * MM_PER_M
        )));
    }
    let field = FieldAt {
        coil: &model.coil,
        didt_a_per_s: model.didt_a_per_s,
        target: *image_point,
        along,
    };
    let params = DoseSearch {
        radius_m: t.radius_m,
        ..DoseSearch::default()
    };
    let over = mocomp_nav::CoilOver {
        scalp,
        solid,
        standoff_m,
        handle: *handle,
    };
    let map = mocomp_nav::dose_search::search(&over, &field, &params)
        .map_err(|e| AppError::Refused(format!("--optimize-dose: {e}")))?;
    let pose = map.best.image_from_coil;
    let under = scalp.nearest(&Point3::from(pose.translation.vector));
    let placement = CoilPlacement {
        image_from_coil: pose,
        scalp_point: under.point,
        depth_m: (image_point - under.point).norm(),
        lift_m: ((pose.translation.vector - under.point.coords).norm() - standoff_m).max(0.0),
    };
    Ok((placement, map))
}

/// Writes the dose search's `map` to `path` as CSV: each place and turn evaluated (its offset
/// from the nearest scalp point in mm, the turn in degrees, the coil's centre in the image in
/// mm, the dose in V/m), in the order evaluated.
pub fn write_dose_map(path: &std::path::Path, map: &DoseMap) -> Result<(), AppError> {
    let what = || format!("--dose-map {}", path.display());
    let mut w =
        csv::Writer::from_path(path).map_err(|e| AppError::Config(format!("{}: {e}", what())))?;
    let write = |w: &mut csv::Writer<std::fs::File>| -> Result<(), csv::Error> {
        w.write_record([
            "offset_u_mm",
            "offset_v_mm",
            "turn_deg",
            "x_mm",
            "y_mm",
            "z_mm",
            "dose_v_per_m",
        ])?;
        for p in &map.evaluated {
            let c = p.image_from_coil.translation.vector * MM_PER_M;
            w.write_record([
                format!("{:.3}", p.offset_m.0 * MM_PER_M),
                format!("{:.3}", p.offset_m.1 * MM_PER_M),
                format!("{:.3}", p.turn_rad.to_degrees()),
                format!("{:.3}", c.x),
                format!("{:.3}", c.y),
                format!("{:.3}", c.z),
                format!("{:.4}", p.dose_v_per_m),
            ])?;
        }
        w.flush()?;
        Ok(())
    };
    write(&mut w).map_err(|e| AppError::Config(format!("{}: {e}", what())))
}

/// Places the target `name` given by `spec`, the coil's face `standoff_m` off the scalp and its
/// handle as `handle` says (or, with `dose`, where and turned as gives the target the largest
/// dose), and checks it as the loop will.
pub fn place_target(
    setup: &Setup,
    name: &str,
    spec: &TargetSpec,
    standoff_m: f64,
    handle: &Handle,
    note: &str,
    dose: Option<&DoseTargeting>,
) -> Result<Placed, AppError> {
    let head = setup.file.head_model()?;
    let head_from_image = setup.file.head.head_from_image.iso();
    let scalp = Reframed::new(head.shape(), head_from_image.inverse());
    let (image_point, source) = resolve(setup, spec)?;
    let coil = setup.file.coil_model();
    let solid = coil
        .solid()
        .map_err(|e| AppError::Config(format!("[coil]: {e}")))?;
    let (placement, map) = match dose {
        None => (
            mocomp_nav::place_coil(&scalp, &solid, &image_point, standoff_m, handle)
                .map_err(|e| AppError::Refused(format!("target {name} ({source}): {e}")))?,
            None,
        ),
        Some(t) => {
            let (p, m) = place_by_dose(setup, &scalp, &solid, &image_point, standoff_m, handle, t)?;
            (p, Some(m))
        }
    };
    let head_from_coil: Isometry3<f64> = head_from_image * placement.image_from_coil;
    check_goal(
        &head,
        &coil,
        &head_from_coil,
        setup.file.params.goal_min_distance_m(),
    )
    .map_err(|e| {
        let why = match e {
            GoalError::InsideHead { .. } => {
                format!("{e} (loop.coil_min_distance_m; a larger --standoff-mm)")
            }
            _ => e.to_string(),
        };
        AppError::Refused(format!("target {name} ({source}): {why}"))
    })?;
    let clearance_m = coil.measured_distance(&head, &head_from_coil);
    let target = Target::new(name, &head_from_coil, note, &targets::now())
        .placed_on_image(&placement.image_from_coil, &source);
    Ok(Placed {
        target,
        placement,
        image_point,
        standoff_m,
        clearance_m,
        dose: map,
    })
}

/// The image point `spec` names and how to say where it came from.
fn resolve(setup: &Setup, spec: &TargetSpec) -> Result<(Point3<f64>, String), AppError> {
    let fmt = |v: &[f64; 3]| format!("({:.1}, {:.1}, {:.1}) mm", v[0], v[1], v[2]);
    Ok(match spec {
        TargetSpec::Image(mm) => (point_from_mm(*mm), format!("image {}", fmt(mm))),
        TargetSpec::Mni(mm, affine) => match affine {
            None => (
                point_from_mm(*mm),
                format!("mni {}, the image in MNI space", fmt(mm)),
            ),
            Some((image_from_mni, file)) => {
                let p = image_from_mni.transform_point(&Point3::from(*mm));
                (
                    p / MM_PER_M,
                    format!(
                        "mni {} through {file}, image {}",
                        fmt(mm),
                        fmt(&p.coords.into())
                    ),
                )
            }
        },
        TargetSpec::Eeg(label) => {
            let all = eeg_positions(setup, System::TenTen)?;
            let found = all
                .iter()
                .find(|p| p.name.eq_ignore_ascii_case(label))
                .ok_or_else(|| {
                    AppError::Config(format!(
                        "--eeg {label}: not a 10-10 position on or above the circumference ({})",
                        all.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
                    ))
                })?;
            (
                found.point,
                format!(
                    "eeg {} (10-10 on the scalp, image {})",
                    found.name,
                    fmt(&mm_from_point(&found.point))
                ),
            )
        }
    })
}
