//! Targets imported from another navigator's file ([`mocomp_navfiles::read`]): coil poses kept
//! as planned (SimNIBS, Localite, Brainsight), points placed as the coil over them (3D Slicer
//! markups), each checked against this patient's scalp before it is kept: a pose far off the
//! scalp, or one whose coil faces away from the head, is a file in another frame or unit, and
//! is refused by name.

use crate::AppError;
use crate::config::Setup;
use crate::navigation::{Placed, TargetSpec, mm_from_point, place_target};
use mocomp_control::goal::check_goal;
use mocomp_head::{HeadShape, Reframed};
use mocomp_nav::Handle;
use mocomp_navfiles::read::{NamedPose, Navigator, parse_poses, slicer_points};
use mocomp_session::Target;

/// How far from the scalp an imported coil's face may be, m: navigators plan the coil on the
/// skin or a few millimetres off (SimNIBS: 4 mm); centimetres off is another frame.
pub const MAX_OFF_SCALP_M: f64 = 0.02;

/// What a file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Coil poses from a navigator.
    Poses(Navigator),
    /// Points from 3D Slicer markups.
    Slicer,
}

impl std::str::FromStr for Source {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("slicer") {
            return Ok(Self::Slicer);
        }
        s.parse::<Navigator>()
            .map(Self::Poses)
            .map_err(|_| format!("{s:?}: simnibs, localite, brainsight or slicer"))
    }
}

/// The targets in `text` (the file `file`, from `source`), checked on `setup`'s scalp; a point
/// is placed `standoff_m` off the scalp with `handle`.
pub fn import(
    setup: &Setup,
    source: Source,
    file: &str,
    text: &str,
    standoff_m: f64,
    handle: &Handle,
) -> Result<Vec<Target>, AppError> {
    match source {
        Source::Poses(navigator) => {
            let poses = parse_poses(navigator, file, text)?;
            poses
                .iter()
                .map(|p| pose_target(setup, navigator, file, p))
                .collect()
        }
        Source::Slicer => slicer_points(file, text)?
            .iter()
            .map(|l| {
                let spec = TargetSpec::Image(mm_from_point(&l.point));
                place_target(setup, &l.name, &spec, standoff_m, handle, "", None).map(
                    |Placed { target, .. }| Target {
                        source: format!("slicer {file}: {}", target.source),
                        ..target
                    },
                )
            })
            .collect(),
    }
}

fn pose_target(
    setup: &Setup,
    navigator: Navigator,
    file: &str,
    p: &NamedPose,
) -> Result<Target, AppError> {
    let head = setup.file.head_model()?;
    let head_from_image = setup.file.head.head_from_image.iso();
    let scalp = Reframed::new(head.shape(), head_from_image.inverse());
    let face = mocomp_geom::nalgebra::Point3::from(p.image_from_coil.translation.vector);
    let off = scalp.signed_distance(&face);
    if !(-0.002..=MAX_OFF_SCALP_M).contains(&off) {
        return Err(AppError::Config(format!(
            "{file}: {}: the coil's face lies {:.1} mm {} the scalp: is the file in this image's \
             frame ({}: {})?",
            p.name,
            off.abs() * 1e3,
            if off > 0.0 { "outside" } else { "inside" },
            navigator.name(),
            navigator.frame_hint()
        )));
    }
    let head_from_coil = head_from_image * p.image_from_coil;
    check_goal(
        &head,
        &setup.file.coil_model(),
        &head_from_coil,
        setup.file.params.goal_min_distance_m(),
    )
    .map_err(|e| AppError::Config(format!("{file}: {}: {e}", p.name)))?;
    let source = format!("{} {file}", navigator.name());
    Ok(Target::new(
        &p.name,
        &head_from_coil,
        "",
        &crate::navigation::targets::now(),
    )
    .placed_on_image(&p.image_from_coil, &source))
}
