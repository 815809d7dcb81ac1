//! What `mocomp targets add` says of a target it placed: where the coil went over the scalp and
//! why, what the dose search found, the target's line, and whether the arm reaches it with the
//! head where it is configured (said, not refused: the placement is what changes).

use crate::AppError;
use crate::config::Setup;
use crate::navigation::placement::Targets;
use crate::navigation::{Placed, mm_from_point};
use mocomp_session::Target;
use std::fmt;
use std::path::Path;

use mocomp_geom::units::MM_PER_M;

/// A placed target as a person reads it.
impl fmt::Display for Placed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = &self.placement;
        let [sx, sy, sz] = mm_from_point(&p.scalp_point);
        write!(
            f,
            "added {} from {}: the coil over the scalp at ({sx:.1}, {sy:.1}, {sz:.1}) mm (image), \
             the target {:.1} mm below it, the face {:.1} mm off the scalp",
            self.target.name,
            self.target.source,
            p.depth_m * MM_PER_M,
            (self.standoff_m + p.lift_m) * MM_PER_M,
        )?;
        if p.lift_m > 1e-4 {
            write!(
                f,
                " (lifted {:.1} mm to clear the scalp around it)",
                p.lift_m * MM_PER_M
            )?;
        }
        writeln!(
            f,
            ", the whole coil {:.1} mm clear of the scalp",
            self.clearance_m * MM_PER_M
        )?;
        if let Some(map) = &self.dose {
            let (best, plain) = (&map.best, &map.plain);
            writeln!(
                f,
                "targeted by dose: {:.1} V/m at the target, {:+.1} % on the coil placed over the \
                 nearest scalp ({:.1} V/m); its centre {:.1} mm from there, turned {:.0}° from the \
                 handle asked; {} places and turns evaluated",
                best.dose_v_per_m,
                100.0 * (best.dose_v_per_m / plain.dose_v_per_m - 1.0),
                plain.dose_v_per_m,
                best.offset_m.0.hypot(best.offset_m.1) * MM_PER_M,
                best.turn_rad.to_degrees().rem_euclid(360.0),
                map.evaluated.len()
            )?;
        }
        writeln!(f, "{}", self.target.line())
    }
}

/// Whether the arm reaches `target` with the head at the configured placement, as lines
/// (`config`: the file `mocomp placement search` should be pointed at). A placement the arm
/// cannot stand at is said too; a goal the loop cannot model is an error.
pub fn reach_lines(setup: &Setup, target: &Target, config: &Path) -> Result<Vec<String>, AppError> {
    let goal = crate::navigation::targets::head_from_coil(setup, target);
    let targets = Targets::new(setup, &[(target.name.clone(), goal)])?;
    let configured = match targets.at_configured(setup) {
        Ok(c) => c,
        Err(e) => return Ok(vec![format!("reach not checked: {e}")]),
    };
    let mut lines = Vec::new();
    for r in &configured.reaches {
        lines.push(format!("at the configured placement: {r}"));
        if r.refusal.is_some() {
            lines.push(format!(
                "NOT REACHABLE where the head is configured (tracker.simulated.base_from_head): \
                 `mocomp placement search --config {}` finds a place that reaches every target",
                config.display()
            ));
        }
    }
    Ok(lines)
}
