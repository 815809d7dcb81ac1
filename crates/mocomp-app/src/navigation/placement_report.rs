//! What `mocomp placement check` and `mocomp placement search` report: each target's reach at
//! the configured placement or at the one found, as lines for a person or one JSON object, and
//! the refusal when the arm does not reach them all.

use crate::AppError;
use crate::navigation::placement::{Configured, Found, Region, TargetReach, pose_vector};
use mocomp_control::compensator::reach::Way;
use mocomp_geom::nalgebra::Isometry3;
use serde_json::{Value, json};
use std::fmt;
use std::path::Path;

use mocomp_geom::units::MM_PER_M;

/// Each target's reach as JSON: reachable, the rule that refuses it, the way there, the arm at
/// the goal.
pub fn reaches_json(reaches: &[TargetReach]) -> Value {
    reaches
        .iter()
        .map(|r| {
            let at = r.reach.at_goal.map(|g| {
                json!({
                    "branch": g.branch.to_string(),
                    "joints_rad": g.joints,
                    "joint_margin_deg": g.joint_margin_rad.to_degrees(),
                    "singularity_margin": g.singularity_margin,
                    "headroom_followed": g.headroom_ok,
                    "headroom_singularity_margin": g.headroom_singularity_margin,
                })
            });
            json!({
                "name": r.name,
                "reachable": r.refusal.is_none(),
                "refusal": r.refusal.map(|x| x.to_string()),
                "refusal_code": r.refusal.map(|x| format!("{x:?}")),
                "way": match r.reach.way {
                    Ok(Way::Shell) => "shell",
                    Ok(Way::Transit(_)) => "transit",
                    Err(_) => "none",
                },
                "at_goal": at,
            })
        })
        .collect()
}

/// A placement as the configuration writes it: metres, then the rotation vector in radians.
pub fn pose_text(p: &Isometry3<f64>) -> String {
    let v = pose_vector(p);
    format!(
        "[{:.3}, {:.3}, {:.3}, {:.4}, {:.4}, {:.4}]",
        v[0], v[1], v[2], v[3], v[4], v[5]
    )
}

/// `placement check`'s JSON.
pub fn configured_json(c: &Configured) -> Value {
    json!({
        "base_from_head": pose_vector(&c.place),
        "rest_joints_rad": c.rest,
        "targets": reaches_json(&c.reaches),
    })
}

/// The refusal when some target is out of reach at the configured placement (`config`: the file
/// to search with).
pub fn configured_refusal(c: &Configured, config: &Path) -> Option<AppError> {
    let refused = c.reaches.iter().filter(|r| r.refusal.is_some()).count();
    (refused > 0).then(|| {
        AppError::Refused(format!(
            "{refused} of {} targets not reachable with the head at \
             tracker.simulated.base_from_head = {}: `mocomp placement search --config {}` finds \
             a place",
            c.reaches.len(),
            pose_text(&c.place),
            config.display()
        ))
    })
}

/// The best placement a search found, against the configured one it searched around.
#[derive(Debug)]
pub struct Searched<'a> {
    found: &'a Found,
    place: &'a Isometry3<f64>,
    score: f64,
    reaches: &'a [TargetReach],
    /// The move from the configured placement, mm, in the robot's base frame.
    moved_mm: [f64; 3],
    /// The turn about the vertical, rad.
    turned_rad: f64,
}

impl<'a> Searched<'a> {
    /// The search's outcome, or the refusal when no placement in `region` reaches every target.
    pub fn new(
        found: &'a Found,
        centre: &Isometry3<f64>,
        region: &Region,
    ) -> Result<Self, AppError> {
        let Some((place, score, reaches)) = &found.best else {
            let [x, y, z] = region.half_m.map(|v| v * MM_PER_M);
            return Err(AppError::Refused(format!(
                "none of {} placements within ±{x:.0}, ±{y:.0}, ±{z:.0} mm and ±{:.0}° of the \
                 configured one reaches every target: a larger --region-mm or --yaw-deg, or fewer \
                 targets",
                found.tried,
                region.yaw_half_rad.to_degrees()
            )));
        };
        let shift = (place.translation.vector - centre.translation.vector) * MM_PER_M;
        Ok(Self {
            found,
            place,
            score: *score,
            reaches,
            moved_mm: [shift.x, shift.y, shift.z],
            turned_rad: (place.rotation * centre.rotation.inverse())
                .euler_angles()
                .2,
        })
    }

    /// The placement found, base_from_head.
    pub fn place(&self) -> &Isometry3<f64> {
        self.place
    }

    /// Each target's reach there.
    pub fn reaches(&self) -> &[TargetReach] {
        self.reaches
    }

    /// `placement search`'s JSON.
    pub fn json(&self) -> Value {
        json!({
            "tried": self.found.tried,
            "reaching": self.found.reaching,
            "score": self.score,
            "base_from_head": pose_vector(self.place),
            "moved_mm": self.moved_mm,
            "turned_deg": self.turned_rad.to_degrees(),
            "targets": reaches_json(self.reaches),
        })
    }
}

/// What a person reads: the search, the configuration's lines to paste, each target's reach.
impl fmt::Display for Searched<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.moved_mm;
        writeln!(
            f,
            "{} placements tried, {} reach every target; the most margin ({:.2}) with the head \
             moved ({x:.0}, {y:.0}, {z:.0}) mm in the robot's base frame and turned {:.0}° about \
             the vertical:",
            self.found.tried,
            self.found.reaching,
            self.score,
            self.turned_rad.to_degrees()
        )?;
        writeln!(f, "[tracker.simulated]")?;
        writeln!(f, "base_from_head = {}", pose_text(self.place))?;
        for r in self.reaches {
            writeln!(f, "  {r}")?;
        }
        Ok(())
    }
}
