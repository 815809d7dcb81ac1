//! The registration's worth where it matters: the bound on its error (95 %) at the goal
//! compensation starts on and at each session target, and the gate that refuses to start beyond
//! `[head] max_tre_mm` unless the operator overrides it (logged in the registration file).

use crate::AppError;
use crate::config::Setup;
use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_head::{HeadShape, Reframed};

use mocomp_geom::units::MM_PER_M;

/// The registration's error bound at the goal compensation starts on, against `[head]
/// max_tre_mm`: `Ok(note)` to print when it is within, or when the operator overrides it with
/// `accept` (the reason, then appended to the registration file); refused otherwise. Nothing to
/// say without a registration.
pub fn registration_gate(setup: &Setup, accept: Option<&str>) -> Result<Option<String>, AppError> {
    let Some((path, record)) = &setup.file.loaded.registered else {
        return Ok(None);
    };
    let (target, head_from_coil) = start_goal(setup)?;
    let head = setup.file.head_model()?;
    let image_from_head = setup.file.head.head_from_image.iso().inverse();
    let scalp = Reframed::new(head.shape(), image_from_head);
    // The error where the coil meets the scalp: the point of the scalp nearest its face.
    let under = HeadShape::nearest(
        &scalp,
        &Point3::from((image_from_head * head_from_coil).translation.vector),
    )
    .point;
    let tre_mm = record.tre_at(&under) * MM_PER_M;
    let limit_mm = setup.file.head.max_tre_mm;
    let said = format!(
        "the registration's error at {target} is within {tre_mm:.1} mm ({:.0} % bound; \
         head.max_tre_mm {limit_mm} mm; FRE {:.1} mm, surface RMS {:.1} mm)",
        mocomp_nav::CONFIDENCE * 100.0,
        record.fre_mm,
        record.surface_rms_mm
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
    let mut file = crate::config::registration_file::load(path)?;
    file.overrides
        .push(crate::config::registration_file::Override {
            at: crate::navigation::targets::now(),
            target: target.clone(),
            tre_mm,
            limit_mm,
            reason: reason.to_string(),
        });
    crate::config::registration_file::save(path, &file)?;
    Ok(Some(format!(
        "{said}: over the limit, accepted by the operator ({reason:?}, logged in {})",
        path.display()
    )))
}

/// The error bound (mm) of `record` at each of the session's targets and at `[goal]`, where the
/// coil meets the scalp.
pub fn target_errors(
    setup: &Setup,
    record: &crate::config::registration_file::Record,
) -> Result<Vec<(String, f64)>, AppError> {
    Ok(targets(setup, Some(&record.head_from_image()))?
        .into_iter()
        .map(|t| (t.name, record.tre_at(&t.point) * MM_PER_M))
        .collect())
}

/// Where the registration's error matters: `[goal]` and each of the session's targets, at the
/// scalp point under the coil's centre (image frame). A target placed on the image stays where
/// it is in the image; a taught one stays where it is on the marker, carried into the image by
/// `head_from_image` (the registration's, or else the configuration's).
pub fn targets(
    setup: &Setup,
    head_from_image: Option<&Isometry3<f64>>,
) -> Result<Vec<mocomp_nav::Target>, AppError> {
    let head = setup.file.head_model()?;
    let image_from_head = setup.file.head.head_from_image.iso().inverse();
    let head_from_image = head_from_image
        .copied()
        .unwrap_or_else(|| setup.file.head.head_from_image.iso());
    let scalp = Reframed::new(head.shape(), image_from_head);
    let mut goals: Vec<(String, Isometry3<f64>)> = Vec::new();
    if let Ok(g) = setup.file.head_from_coil() {
        goals.push(("[goal]".into(), image_from_head * g));
    }
    if setup.file.session.targets.is_some() {
        for t in crate::navigation::targets::load(&crate::navigation::targets::session_file(setup))?
            .targets
        {
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
        .map(|(name, image_from_coil)| mocomp_nav::Target {
            name,
            point: HeadShape::nearest(&scalp, &Point3::from(image_from_coil.translation.vector))
                .point,
        })
        .collect())
}

/// The goal the loop starts on: `[session] target` in its targets file, else `[goal]`.
fn start_goal(setup: &Setup) -> Result<(String, Isometry3<f64>), AppError> {
    if let (Some(name), Some(_)) = (&setup.file.session.target, &setup.file.session.targets) {
        let targets =
            crate::navigation::targets::load(&crate::navigation::targets::session_file(setup))?;
        let t = targets
            .get(name)
            .map_err(|e| AppError::Config(format!("session.target: {e}")))?;
        return Ok((
            name.clone(),
            crate::navigation::targets::head_from_coil(setup, t),
        ));
    }
    Ok(("[goal]".into(), setup.file.head_from_coil()?))
}
