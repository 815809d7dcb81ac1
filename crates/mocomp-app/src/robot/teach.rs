//! Teaching the goal (`mocomp teach-goal`): the coil's current pose relative to the head becomes
//! the goal. The operator places the coil (freedrive, or the pendant), the robot holds still, the head
//! marker is averaged over a number of samples, and
//! `head_from_coil = (base_from_tracker · tracker_from_head)⁻¹ · base_from_flange · flange_from_coil`
//! is written to the configuration's `[goal] head_from_coil`, in place, keeping every comment.
//! The goal is checked first: the coil must be outside the head model and its axis must point
//! into the head (the planner approaches along it).

use crate::config::Setup;
use crate::world::World;
use crate::{AppError, Context};
use mocomp_control::{GoalError, check_goal};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{PoseSource, rotation_error, translation_error};
use mocomp_ur::Robot;
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

/// What was taught.
#[derive(Debug, Clone, Copy)]
pub struct Taught {
    /// The new goal.
    pub head_from_coil: Isometry3<f64>,
    /// Spread of the head samples (RMS about their mean), m and rad.
    pub spread: (f64, f64),
    /// The coil's distance to the head model's surface, m.
    pub distance_m: f64,
    /// Head samples averaged.
    pub samples: usize,
    /// The goal before, head_from_coil (if there was one).
    pub previous: Option<Isometry3<f64>>,
}

impl Taught {
    /// The report: the samples, the coil's distance to the head model, the change from the
    /// previous goal, and the goal as the configuration file writes it (UR pose vector).
    pub fn text(&self) -> String {
        let six = |v: [f64; 6]| {
            v.iter()
                .map(|x| format!("{x:.6}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let mut s = format!(
            "head samples: {} averaged, spread {:.3} mm, {:.3}° RMS\ncoil face {:.1} mm from the head model",
            self.samples,
            self.spread.0 * 1e3,
            self.spread.1.to_degrees(),
            self.distance_m * 1e3
        );
        if let Some(old) = &self.previous {
            s += &format!(
                "; {:.1} mm and {:.2}° from the previous goal",
                translation_error(&self.head_from_coil, old) * 1e3,
                rotation_error(&self.head_from_coil, old).to_degrees()
            );
        }
        let pose = mocomp_geom::ur_pose_from_iso(&self.head_from_coil);
        s += &format!("\ngoal.head_from_coil = [{}]\n", six(pose));
        if let Some(old) = &self.previous {
            let pose = mocomp_geom::ur_pose_from_iso(old);
            s += &format!("previous            = [{}]\n", six(pose));
        }
        s
    }
}

/// The largest spread (RMS about the mean) of the head samples: beyond it the head moved.
const MAX_SPREAD_M: f64 = 1e-3;
/// The same for rotation (0.5°).
const MAX_SPREAD_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// Writes `value` as `[goal] head_from_coil` in the TOML `text`, keeping everything else.
pub fn set_goal(text: &str, value: &[f64; 6]) -> Result<String, AppError> {
    let mut doc: toml_edit::DocumentMut = text
        .parse()
        .map_err(|e| AppError::Config(format!("cannot edit the configuration: {e}")))?;
    let mut array = toml_edit::Array::new();
    for v in value {
        // Ten significant decimals: sub-micrometre, sub-microradian.
        array.push((v * 1e10).round() / 1e10);
    }
    let goal = doc
        .entry("goal")
        .or_insert(toml_edit::table())
        .as_table_like_mut()
        .ok_or_else(|| AppError::Config("goal: is not a table".into()))?;
    // The old value's comment described the old value: say where the new one came from.
    let mut item = toml_edit::Value::Array(array);
    item.decor_mut().set_prefix(" ");
    item.decor_mut()
        .set_suffix("  # taught by mocomp teach-goal");
    goal.insert("head_from_coil", toml_edit::Item::Value(item));
    Ok(doc.to_string())
}

/// Averages head samples and computes the goal (the robot must be still).
fn teach_on(setup: &Setup, world: &mut World, samples: usize) -> Result<Taught, AppError> {
    let file = &setup.file;
    let client = world.client(setup, &file.tracker.device);
    let mut source = client.pose_source();
    let start = Instant::now();
    let mut heads = Vec::with_capacity(samples);
    let mut q = None;
    // Polled faster than the tracker sends: each sample counts once.
    let mut last = f64::NEG_INFINITY;
    while heads.len() < samples {
        if start.elapsed() > Duration::from_secs(5) {
            refuse!(
                "the head marker ({}) gave {} valid samples in 5 s (need {samples}): is it in view?",
                file.tracker.device,
                heads.len()
            );
        }
        if let Some(s) = source.latest()
            && s.valid
            && s.acquired_s > last
        {
            last = s.acquired_s;
            heads.push(s.tracker_from_marker);
        }
        if let Some(r) = world.robot.state() {
            if let Some(f) = r.fault() {
                refuse!("the robot reports {f}");
            }
            if r.actual_qd.iter().any(|v| v.abs() > 1e-3) {
                refuse!("the robot is moving: teach the goal with the coil held still");
            }
            q = Some(r.actual_q);
        }
        world
            .robot
            .keep_alive()
            .what(|| "keeping the robot's program running")?;
        std::thread::sleep(Duration::from_millis(2));
    }
    let Some(q) = q else {
        refuse!("no robot state");
    };
    goal_from(setup, &heads, &q)
}

/// The goal from head marker samples (`tracker_from_head`, the head still) and the robot's
/// joints (the coil still): their mean, its spread, and the loop's goal check.
fn goal_from(setup: &Setup, heads: &[Isometry3<f64>], q: &[f64; 6]) -> Result<Taught, AppError> {
    let file = &setup.file;
    let mean = mocomp_geom::average(heads, None).what(|| "averaging the head samples")?;
    let n = heads.len() as f64;
    let spread = (
        (heads
            .iter()
            .map(|h| translation_error(h, &mean).powi(2))
            .sum::<f64>()
            / n)
            .sqrt(),
        (heads
            .iter()
            .map(|h| rotation_error(h, &mean).powi(2))
            .sum::<f64>()
            / n)
            .sqrt(),
    );
    // A head that moved while being averaged gives a smeared goal.
    if spread.0 > MAX_SPREAD_M || spread.1 > MAX_SPREAD_RAD {
        refuse!(
            "the head moved while the goal was taught (spread {:.2} mm, {:.2}° RMS; at most \
             {} mm, {}°): teach again with the head still",
            spread.0 * 1e3,
            spread.1.to_degrees(),
            MAX_SPREAD_M * 1e3,
            MAX_SPREAD_RAD.to_degrees()
        );
    }
    let base_from_head = setup.base_from_tracker * mean;
    let head_from_coil =
        base_from_head.inverse() * setup.arm.fk_flange(q) * file.flange_from_coil()?;
    // The loop's own goal check (the whole coil model against the head model, the approach axis
    // into the head), so a goal taught here is never one the loop refuses.
    let distance_m = match check_goal(
        &file.head_model()?,
        &file.coil_model(),
        &head_from_coil,
        file.params.goal_min_distance_m(),
    ) {
        Ok(d) => d,
        Err(e @ GoalError::InsideHead { .. }) => refuse!(
            "{e} (loop.coil_min_distance_m): check the calibration, the coil mounting, [head] \
             and [coil]"
        ),
        Err(GoalError::AxisOutward) => refuse!(
            "the coil's +z axis points away from the head: the loop approaches along it (check \
             calibration.flange_from_coil)"
        ),
        Err(e @ (GoalError::NotFinite | GoalError::NearScanEdge { .. })) => refuse!("{e}"),
    };
    Ok(Taught {
        head_from_coil,
        spread,
        distance_m,
        samples: heads.len(),
        previous: file.head_from_coil().ok(),
    })
}

/// Joint motion across a live teaching window beyond which the coil was not held still, rad.
const MAX_JOINT_MOTION_RAD: f64 = 1e-3;
/// Fewest head estimates a live teaching window needs.
pub const MIN_LIVE_SAMPLES: usize = 50;

/// Teaches the goal while the loop runs, held (the console's "teach goal"): from the loop's own
/// head estimates and measured joints of its last cycles (`(tracker_from_head, joints)`, oldest
/// first). The head and the coil must have stood still over them.
pub fn teach_live(
    setup: &Setup,
    window: &[(Isometry3<f64>, [f64; 6])],
) -> Result<Taught, AppError> {
    if window.len() < MIN_LIVE_SAMPLES {
        refuse!(
            "the loop has {} head estimates of the last cycles (need {MIN_LIVE_SAMPLES}): is the \
             head marker in view?",
            window.len()
        );
    }
    let Some(&(_, q)) = window.last() else {
        refuse!("no robot state");
    };
    let moved = window
        .iter()
        .flat_map(|(_, w)| w.iter().zip(&q).map(|(a, b)| (a - b).abs()))
        .fold(0.0f64, f64::max);
    // NaN joints (no reading) count as moved.
    if moved.is_nan() || moved > MAX_JOINT_MOTION_RAD {
        refuse!(
            "the robot moved while the goal was taught ({:.2}° at a joint): hold the loop and \
             let the coil stand still",
            moved.to_degrees()
        );
    }
    let heads: Vec<Isometry3<f64>> = window.iter().map(|(h, _)| *h).collect();
    goal_from(setup, &heads, &q)
}

/// Connects `setup`'s world and teaches the goal from `samples` head samples (the robot must
/// hold still). `notice` is told what starts.
pub fn teach(setup: &Setup, samples: usize, notice: &mut dyn Write) -> Result<Taught, AppError> {
    if samples == 0 {
        return Err(AppError::Config("--samples: must be at least 1".into()));
    }
    let q0 = setup.initial_joints()?;
    setup.needs_igtl_tracker("teach-goal")?;
    let mut world = World::connect_feeding_watchdog(setup, q0, notice)?;
    let taught = teach_on(setup, &mut world, samples);
    // Nothing moved: a failed close changes nothing.
    world.robot.close().ok();
    mocomp_rt::leave_realtime().ok();
    taught
}

/// Writes the taught goal into the configuration file at `path` as `[goal] head_from_coil`,
/// keeping everything else; through a file beside it and a rename, so an interruption never
/// leaves half a file.
pub fn write_goal(path: &Path, taught: &Taught) -> Result<(), AppError> {
    let text = std::fs::read_to_string(path).what(|| format!("--config {}", path.display()))?;
    let edited = set_goal(
        &text,
        &mocomp_geom::ur_pose_from_iso(&taught.head_from_coil),
    )?;
    crate::files::whole::write_whole(path, edited.as_bytes(), "the configuration")
}

/// Writes the taught pose as the target `name` (with `note`, taught now) into the targets file
/// `file`, replacing a target of that name.
pub fn write_taught(file: &Path, name: &str, note: &str, taught: &Taught) -> Result<(), AppError> {
    use crate::navigation::targets;
    let target = mocomp_session::Target::new(name, &taught.head_from_coil, note, &targets::now());
    targets::teach_all(file, &[target])
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn the_goal_is_replaced_in_place_and_comments_survive() {
        let text = "# top comment\n[robot]\nmodel = \"ur3e\" # the arm\n\n[goal]\nhead_from_coil = [0.0, 0.0, 0.1, 3.14, 0.0, 0.0]  # on top\n\n[loop]\npredict = true\n";
        let out = set_goal(text, &[0.01, -0.02, 0.12, 3.0, 0.1, -0.2]).unwrap();
        assert!(out.contains("# top comment"), "{out}");
        assert!(out.contains("model = \"ur3e\" # the arm"), "{out}");
        assert!(
            !out.contains("# on top"),
            "the old value's comment goes: {out}"
        );
        assert!(out.contains("# taught by mocomp teach-goal"), "{out}");
        assert!(out.contains("predict = true"), "{out}");
        let v: toml::Value = toml::from_str(&out).unwrap();
        let g: Vec<f64> = v["goal"]["head_from_coil"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_float().unwrap())
            .collect();
        assert_eq!(g, vec![0.01, -0.02, 0.12, 3.0, 0.1, -0.2]);
        // A file without a [goal] gets one.
        let out = set_goal(
            "[robot]\nmodel = \"ur3\"\n",
            &[0.0, 0.0, 0.1, 0.0, 0.0, 0.0],
        )
        .unwrap();
        let v: toml::Value = toml::from_str(&out).unwrap();
        assert_eq!(v["goal"]["head_from_coil"].as_array().unwrap().len(), 6);
        assert!(set_goal("goal = 3\n", &[0.0; 6]).is_err());
        assert!(set_goal("[goal\n", &[0.0; 6]).is_err());
    }
}
