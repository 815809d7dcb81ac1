//! `mocomp teach-goal --config FILE`: the coil's current pose relative to the head becomes the
//! goal. The operator places the coil (freedrive, or the pendant), the robot holds still, the head
//! marker is averaged over a number of samples, and
//! `head_from_coil = (base_from_tracker · tracker_from_head)⁻¹ · base_from_flange · flange_from_coil`
//! is written to the configuration's `[goal] head_from_coil`, in place, keeping every comment.
//! The goal is checked first: the coil must be outside the head model and its axis must point
//! into the head (the planner approaches along it).

use crate::UsageError;
use crate::run_config::{initial_joints, pose};
use crate::world::{Setup, World};
use anyhow::Context;
use mocomp_control::{GoalError, check_goal};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{PoseSource, rotation_error, translation_error, ur_pose_from_iso};
use mocomp_ur::Robot;
use std::io::Write;
use std::time::{Duration, Instant};

/// Options from the command line.
#[derive(Debug, Clone)]
pub struct TeachOptions {
    /// The configuration file (rewritten in place unless `dry_run`).
    pub config: String,
    /// Head samples to average.
    pub samples: usize,
    /// Print the goal without writing it.
    pub dry_run: bool,
}

/// What was taught.
#[derive(Debug, Clone, Copy)]
pub struct Taught {
    /// The new goal.
    pub head_from_coil: Isometry3<f64>,
    /// Spread of the head samples (RMS about their mean), m and rad.
    pub spread: (f64, f64),
    /// The coil's distance to the head model's surface, m.
    pub distance_m: f64,
}

/// The largest spread (RMS about the mean) of the head samples: beyond it the head moved.
const MAX_SPREAD_M: f64 = 1e-3;
/// The same for rotation (0.5°).
const MAX_SPREAD_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;

/// Writes `value` as `[goal] head_from_coil` in the TOML `text`, keeping everything else.
pub fn set_goal(text: &str, value: &[f64; 6]) -> Result<String, UsageError> {
    let mut doc: toml_edit::DocumentMut = text
        .parse()
        .map_err(|e| UsageError(format!("cannot edit the configuration: {e}")))?;
    let mut array = toml_edit::Array::new();
    for v in value {
        // Ten significant decimals: sub-micrometre, sub-microradian.
        array.push((v * 1e10).round() / 1e10);
    }
    let goal = doc
        .entry("goal")
        .or_insert(toml_edit::table())
        .as_table_like_mut()
        .ok_or_else(|| UsageError("goal: is not a table".into()))?;
    // The old value's comment described the old value: say where the new one came from.
    let mut item = toml_edit::Value::Array(array);
    item.decor_mut().set_prefix(" ");
    item.decor_mut()
        .set_suffix("  # taught by mocomp teach-goal");
    goal.insert("head_from_coil", toml_edit::Item::Value(item));
    Ok(doc.to_string())
}

/// Averages head samples and computes the goal (the robot must be still).
fn teach(setup: &Setup, world: &mut World, samples: usize) -> anyhow::Result<Taught> {
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
        world.robot.keep_alive()?;
        std::thread::sleep(Duration::from_millis(2));
    }
    let Some(q) = q else {
        refuse!("no robot state");
    };
    let mean = mocomp_geom::average(&heads, None).context("averaging the head samples")?;
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
    let flange_from_coil = pose(
        "calibration.flange_from_coil",
        &file.calibration.flange_from_coil,
    )?;
    let base_from_head = setup.base_from_tracker * mean;
    let head_from_coil = base_from_head.inverse() * setup.arm.fk_flange(&q) * flange_from_coil;
    let period = setup.model.spec().series.period_s();
    let cfg = setup.file.loop_config(setup.base_from_tracker, period)?;
    // The loop's own goal check (the whole coil model against the head model, the approach axis
    // into the head), so a goal taught here is never one the loop refuses.
    let distance_m = match check_goal(
        &cfg.head,
        &cfg.coil,
        &head_from_coil,
        file.params.coil_min_distance_m,
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
        Err(e @ GoalError::NotFinite) => refuse!("{e}"),
    };
    Ok(Taught {
        head_from_coil,
        spread,
        distance_m,
    })
}

/// Runs `teach-goal`.
pub fn run(out: &mut dyn Write, opts: &TeachOptions) -> anyhow::Result<()> {
    if opts.samples == 0 {
        return Err(UsageError("--samples: must be at least 1".into()).into());
    }
    let setup = Setup::load(&opts.config)?;
    let text = std::fs::read_to_string(&opts.config)
        .with_context(|| format!("--config {}", opts.config))?;
    let period = setup.model.spec().series.period_s();
    let cfg = setup.file.loop_config(setup.base_from_tracker, period)?;
    let q0 = initial_joints(&setup.file, &setup.arm, &cfg)?;
    let mut world = World::connect(&setup, q0, out, None)?;
    let taught = teach(&setup, &mut world, opts.samples);
    let _ = world.robot.close();
    let t = taught?;
    let old = cfg.head_from_coil_goal;
    let v = ur_pose_from_iso(&t.head_from_coil);
    writeln!(
        out,
        "head samples: {} averaged, spread {:.3} mm, {:.3}° RMS",
        opts.samples,
        t.spread.0 * 1e3,
        t.spread.1.to_degrees()
    )?;
    writeln!(
        out,
        "coil face {:.1} mm from the head model; {:.1} mm and {:.2}° from the previous goal",
        t.distance_m * 1e3,
        translation_error(&t.head_from_coil, &old) * 1e3,
        rotation_error(&t.head_from_coil, &old).to_degrees()
    )?;
    writeln!(
        out,
        "goal.head_from_coil = [{}]",
        v.iter()
            .map(|x| format!("{x:.6}"))
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    writeln!(
        out,
        "previous            = [{}]",
        ur_pose_from_iso(&old)
            .iter()
            .map(|x| format!("{x:.6}"))
            .collect::<Vec<_>>()
            .join(", ")
    )?;
    if opts.dry_run {
        writeln!(out, "--dry-run: {} not changed", opts.config)?;
        return Ok(());
    }
    let edited = set_goal(&text, &v)?;
    // Write beside it and rename, so an interruption never leaves half a file.
    let tmp = format!("{}.tmp", opts.config);
    std::fs::write(&tmp, edited).with_context(|| format!("writing {tmp}"))?;
    std::fs::rename(&tmp, &opts.config).with_context(|| format!("replacing {}", opts.config))?;
    writeln!(out, "wrote the goal to {}", opts.config)?;
    Ok(())
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
