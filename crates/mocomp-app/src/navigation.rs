//! Navigation on the configuration's head: the image's landmarks (`[head.landmarks]`, mm at the
//! file, metres from here on), the scalp seen in the image's frame, the 10-20 positions on it,
//! and a target in the image (a point, an MNI coordinate, an EEG position) placed as a coil goal
//! in the head marker's frame, through `[head] head_from_image`.

use crate::AppError;
use crate::config::Setup;
use mocomp_control::goal::{GoalError, check_goal};
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Point3};
use mocomp_head::{CoilSolid, Reframed};
use mocomp_nav::{CoilPlacement, CranialLandmarks, EegPosition, Handle, System};
use mocomp_session::Target;

/// Millimetres in a metre: the configuration's and the command line's landmarks and targets
/// are in mm.
const MM_PER_M: f64 = 1000.0;

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
    let get =
        |name: &str| {
            marks
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, v)| point_from_mm(*v))
            .ok_or_else(|| {
                AppError::Config(format!(
                    "head.landmarks: no {name} (the 10-20 system is measured from nasion, inion, \
                     lpa and rpa, image RAS in mm){}",
                    if marks.is_empty() {
                        String::new()
                    } else {
                        format!("; it has {}", marks.keys().cloned().collect::<Vec<_>>().join(", "))
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

/// The head model of `setup`, which must be a scan's scalp: an ellipsoid has no image frame.
fn scan_head(setup: &Setup) -> Result<mocomp_control::HeadModel, AppError> {
    if setup.file.head.mesh.is_none() {
        return Err(AppError::Config(
            "head.mesh: navigation on the image needs the patient's scalp from the scan (the \
             ellipsoid has no image frame)"
                .into(),
        ));
    }
    setup.file.head_model()
}

/// The positions of `system` on the scalp of `setup`, image frame.
pub fn eeg_positions(setup: &Setup, system: System) -> Result<Vec<EegPosition>, AppError> {
    let head = scan_head(setup)?;
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
    /// The whole coil's clearance from the scalp at the goal, m (exact; the loop's goal check,
    /// which passed, measures it conservatively).
    pub clearance_m: f64,
}

/// Places the target `name` given by `spec`, the coil's face `standoff_m` off the scalp and its
/// handle as `handle` says, and checks it as the loop will.
pub fn place_target(
    setup: &Setup,
    name: &str,
    spec: &TargetSpec,
    standoff_m: f64,
    handle: &Handle,
    note: &str,
) -> Result<Placed, AppError> {
    let head = scan_head(setup)?;
    let head_from_image = setup.file.head.head_from_image.iso();
    let scalp = Reframed::new(head.shape(), head_from_image.inverse());
    let (image_point, source) = resolve(setup, spec)?;
    let coil = setup.file.coil_model();
    let solid = CoilSolid::new(coil.radius, coil.thickness)
        .map_err(|e| AppError::Config(format!("[coil]: {e}")))?;
    let placement = mocomp_nav::place_coil(&scalp, &solid, &image_point, standoff_m, handle)
        .map_err(|e| AppError::Refused(format!("target {name} ({source}): {e}")))?;
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
    let target = Target::new(name, &head_from_coil, note, &crate::targets::now())
        .placed_on_image(&placement.image_from_coil, &source);
    Ok(Placed {
        target,
        placement,
        image_point,
        clearance_m,
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

/// The registration's estimated error at the goal compensation starts on, against `[head]
/// max_tre_mm`: `Ok(note)` to print when it is within, or when the operator overrides it with
/// `accept` (the reason, then appended to the registration file); refused otherwise. Nothing to
/// say without a registration.
pub fn registration_gate(setup: &Setup, accept: Option<&str>) -> Result<Option<String>, AppError> {
    let Some((path, record)) = &setup.file.head.registered else {
        return Ok(None);
    };
    let (target, head_from_coil) = start_goal(setup)?;
    let head = scan_head(setup)?;
    let image_from_head = setup.file.head.head_from_image.iso().inverse();
    let scalp = Reframed::new(head.shape(), image_from_head);
    // The error where the coil meets the scalp: the point of the scalp nearest its face.
    let under = mocomp_head::HeadShape::nearest(
        &scalp,
        &Point3::from((image_from_head * head_from_coil).translation.vector),
    )
    .point;
    let tre_mm = record.tre_at(&under) * MM_PER_M;
    let limit_mm = setup.file.head.max_tre_mm;
    let said = format!(
        "the registration's estimated target error at {target} is {tre_mm:.1} mm (head.max_tre_mm \
         {limit_mm} mm; FRE {:.1} mm, surface RMS {:.1} mm)",
        record.fre_mm, record.surface_rms_mm
    );
    if tre_mm <= limit_mm {
        return Ok(Some(said));
    }
    let Some(reason) = accept.filter(|r| !r.trim().is_empty()) else {
        return Err(AppError::Refused(format!(
            "{said}: register again (touch the landmarks with care, sweep more of the scalp), or \
             start with --accept-registration \"why\" (logged in {})",
            path.display()
        )));
    };
    let mut file = crate::registration_file::load(path)?;
    file.overrides.push(crate::registration_file::Override {
        at: crate::targets::now(),
        target: target.clone(),
        tre_mm,
        limit_mm,
        reason: reason.to_string(),
    });
    crate::registration_file::save(path, &file)?;
    Ok(Some(format!(
        "{said}: over the limit, accepted by the operator ({reason:?}, logged in {})",
        path.display()
    )))
}

/// The estimated target error (mm) of `record` at each of the session's targets and at
/// `[goal]`, where the coil meets the scalp.
pub fn target_errors(
    setup: &Setup,
    record: &crate::registration_file::Record,
) -> Result<Vec<(String, f64)>, AppError> {
    let head = scan_head(setup)?;
    let head_from_image = record.head_from_image();
    let image_from_head = setup.file.head.head_from_image.iso().inverse();
    let scalp = Reframed::new(head.shape(), image_from_head);
    let mut goals: Vec<(String, Isometry3<f64>)> = Vec::new();
    if let Ok(g) = setup.file.head_from_coil() {
        goals.push(("[goal]".into(), image_from_head * g));
    }
    if setup.file.session.targets.is_some() {
        for t in crate::targets::load(&crate::targets::session_file(setup))?.targets {
            // A target placed on the image stays where it is in the image under a new
            // registration; a taught one stays where it is on the marker.
            let image_from_coil = match t.image_from_coil {
                Some(p) => Isometry3::new(
                    mocomp_geom::nalgebra::Vector3::new(p[0], p[1], p[2]),
                    mocomp_geom::nalgebra::Vector3::new(p[3], p[4], p[5]),
                ),
                None => head_from_image.inverse() * t.pose(),
            };
            goals.push((t.name.clone(), image_from_coil));
        }
    }
    Ok(goals
        .into_iter()
        .map(|(name, image_from_coil)| {
            let under = mocomp_head::HeadShape::nearest(
                &scalp,
                &Point3::from(image_from_coil.translation.vector),
            )
            .point;
            (name, record.tre_at(&under) * MM_PER_M)
        })
        .collect())
}

/// The goal the loop starts on: `[session] target` in its targets file, else `[goal]`.
fn start_goal(setup: &Setup) -> Result<(String, Isometry3<f64>), AppError> {
    if let (Some(name), Some(_)) = (&setup.file.session.target, &setup.file.session.targets) {
        let targets = crate::targets::load(&crate::targets::session_file(setup))?;
        let t = targets
            .get(name)
            .map_err(|e| AppError::Config(format!("session.target: {e}")))?;
        return Ok((name.clone(), crate::targets::head_from_coil(setup, t)));
    }
    Ok(("[goal]".into(), setup.file.head_from_coil()?))
}

/// Reads an affine (image_from_mni, millimetres) from a text file: four rows of four numbers
/// (blank lines and `#` comments skipped), the last row 0 0 0 1.
pub fn read_affine(path: &std::path::Path) -> Result<Matrix4<f64>, AppError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .map_err(|e| AppError::failed(format!("reading the affine {name}"), e))?;
    parse_affine(&name, &text)
}

/// [`read_affine`] on the text of `file`.
pub fn parse_affine(file: &str, text: &str) -> Result<Matrix4<f64>, AppError> {
    let bad = |line: usize, why: String| AppError::Config(format!("{file}:{line}: {why}"));
    let mut rows: Vec<[f64; 4]> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let body = line.split('#').next().unwrap_or("").trim();
        if body.is_empty() {
            continue;
        }
        if rows.len() == 4 {
            return Err(bad(line_no, "more than four rows".into()));
        }
        let v: Vec<&str> = body
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .collect();
        if v.len() != 4 {
            return Err(bad(line_no, format!("{} numbers, a row has 4", v.len())));
        }
        let mut row = [0.0; 4];
        for (k, (slot, s)) in row.iter_mut().zip(&v).enumerate() {
            *slot = s
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    bad(
                        line_no,
                        format!("column {}: {s:?} is not a finite number", k + 1),
                    )
                })?;
        }
        rows.push(row);
    }
    if rows.len() != 4 {
        return Err(AppError::Config(format!(
            "{file}: {} rows, an affine has 4",
            rows.len()
        )));
    }
    let last = rows[3];
    if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > 1e-9 {
        return Err(AppError::Config(format!(
            "{file}: the last row is {last:?}, an affine's is 0 0 0 1"
        )));
    }
    let m = Matrix4::from_fn(|r, c| rows[r][c]);
    if m.fixed_view::<3, 3>(0, 0).determinant().abs() < 1e-9 {
        return Err(AppError::Config(format!(
            "{file}: the affine is singular (it flattens space)"
        )));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn an_affine_file_is_read_and_every_fault_is_named_by_line() {
        let m = parse_affine(
            "a.txt",
            "# image_from_mni\n1 0 0 -2\n0 1 0 3.5\n\n0,0,1,4\n0 0 0 1\n",
        )
        .unwrap();
        assert_eq!(
            m.transform_point(&Point3::origin()),
            Point3::new(-2.0, 3.5, 4.0)
        );
        for (text, says) in [
            ("1 0 0\n", "a.txt:1: 3 numbers"),
            ("1 0 0 0\n0 1 0 0\n0 0 1 x\n0 0 0 1\n", "a.txt:3: column 4"),
            ("1 0 0 0\n0 1 0 0\n0 0 1 0\n", "3 rows"),
            ("1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n", "last row"),
            ("1 0 0 0\n0 1 0 0\n0 0 0 0\n0 0 0 1\n", "singular"),
            (
                "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n0 0 0 1\n",
                "a.txt:5: more than four",
            ),
        ] {
            let e = parse_affine("a.txt", text).unwrap_err().to_string();
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }
}
