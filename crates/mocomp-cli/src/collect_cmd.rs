//! `mocomp calibrate collect --config FILE`: runs the calibration planner's poses on the robot,
//! records the tracker's measurement of the flange's marker at each (with a progress bar),
//! solves `AX = YB`, prints the report and saves the calibration (and the pairs, for
//! `calibrate solve`).

use crate::run_config::{CollectSection, initial_joints, pose};
use crate::world::{Setup, World};
use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use mocomp_calib::plan::{PlanOptions, TrackerView, plan};
use mocomp_calib::{NoiseModel, Pair, PairsFormat, SolveOptions, solve, write_pairs_csv};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{PoseSource, rotation_error, translation_error};
use mocomp_ur::{Robot, UrRobot};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Options from the command line.
#[derive(Debug, Clone)]
pub struct CollectOptions {
    /// The configuration file.
    pub config: String,
    /// Overrides `calibrate.out` (relative to the current directory).
    pub out: Option<PathBuf>,
    /// No progress bar.
    pub quiet: bool,
}

/// Keeps the watchdog fed for `d`.
fn keep_fed(robot: &mut UrRobot, d: Duration) -> anyhow::Result<()> {
    let end = Instant::now() + d;
    while Instant::now() < end {
        robot.keep_alive()?;
        std::thread::sleep(Duration::from_millis(8));
    }
    Ok(())
}

/// Moves to `q` and waits (keeping the watchdog fed) until the robot is there and still.
fn move_to(robot: &mut UrRobot, q: &[f64; 6], c: &CollectSection) -> anyhow::Result<()> {
    let seq = robot.move_joints(q, c.joint_speed_rad_s, c.joint_accel_rad_s2)?;
    let start = Instant::now();
    loop {
        if let Some(s) = robot.state() {
            if let Some(f) = s.fault() {
                refuse!("the robot stopped during a calibration move: {f}");
            }
            let there = s.actual_q.iter().zip(q).all(|(a, b)| (a - b).abs() < 2e-3);
            let still = s.actual_qd.iter().all(|v| v.abs() < 2e-3);
            if there && still {
                return Ok(());
            }
            if s.move_done_seq >= seq && still {
                refuse!("a calibration move ended away from its target");
            }
        }
        if start.elapsed().as_secs_f64() > c.move_timeout_s {
            refuse!(
                "a calibration move did not arrive within calibrate.move_timeout_s = {} s",
                c.move_timeout_s
            );
        }
        robot.keep_alive()?;
        std::thread::sleep(Duration::from_millis(4));
    }
}

/// One measurement: the mean of `n` valid samples acquired after `after` (on the world's clock),
/// with the robot's joints averaged over the same time. `None` when the marker is not seen.
fn measure(
    world: &mut World,
    source: &mut dyn PoseSource,
    n: usize,
    after: f64,
) -> anyhow::Result<Option<([f64; 6], Isometry3<f64>)>> {
    let start = Instant::now();
    let mut samples = Vec::with_capacity(n);
    let mut qs = Vec::new();
    // Polled faster than the tracker sends: each sample counts once.
    let mut last = after;
    while samples.len() < n {
        if start.elapsed() > Duration::from_secs(3) {
            return Ok(None);
        }
        if let Some(s) = source.latest()
            && s.valid
            && s.acquired_s > last
        {
            last = s.acquired_s;
            samples.push(s.tracker_from_marker);
            if let Some(r) = world.robot.state() {
                qs.push(r.actual_q);
            }
        }
        world.robot.keep_alive()?;
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut q = [0.0; 6];
    for qi in &qs {
        for (a, b) in q.iter_mut().zip(qi) {
            *a += b / qs.len().max(1) as f64;
        }
    }
    Ok(mocomp_geom::average(&samples, None).ok().map(|p| (q, p)))
}

/// Runs the collection, solves and saves.
pub fn collect(out: &mut dyn Write, opts: &CollectOptions) -> anyhow::Result<()> {
    let setup = Setup::load(&opts.config)?;
    let c = setup.file.calibrate.clone();
    let arm = setup.arm;
    let period = setup.model.spec().series.period_s();
    let cfg = setup.file.loop_config(setup.base_from_tracker, period)?;
    let q0 = initial_joints(&setup.file, &arm, &cfg)?;
    let mut world = World::connect(&setup, q0, out, None)?;
    let client = world.client(&setup, &c.device);
    let mut source = client.pose_source();

    // Where the robot is: the run starts and ends here.
    let t0 = Instant::now();
    let current = loop {
        if let Some(s) = world.robot.state() {
            break s.actual_q;
        }
        if t0.elapsed() > Duration::from_secs(5) {
            refuse!("no robot state within 5 s");
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let center = match &c.center {
        Some(p) => pose("calibrate.center", p)?,
        None => arm.fk_flange(&current),
    };
    let mut o = PlanOptions::new(c.poses, center, current);
    o.rotation_range_rad = (c.min_rotation_rad, c.max_rotation_rad);
    o.translation_spread_m = c.spread_m;
    o.flange_from_marker = pose(
        "calibrate.flange_from_marker_guess",
        &c.flange_from_marker_guess,
    )?;
    o.tracker = c
        .check_view
        .then(|| TrackerView::typical(setup.base_from_tracker));
    // Planning takes long in a debug build or on a busy machine: the running program's watchdog
    // is fed meanwhile.
    let poses = world.robot.keep_alive_while(|| plan(&arm, &o))??;
    writeln!(
        out,
        "{} calibration poses around the flange at [{}]; the arm will move: keep the space clear",
        poses.len(),
        crate::print::row(&mocomp_geom::ur_pose_from_iso(&center))
    )?;
    out.flush()?;

    let bar = if opts.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(poses.len() as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{bar:30}] {pos}/{len} poses, {elapsed} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar.set_prefix("collecting");
    let mut pairs = Vec::new();
    let mut missed = Vec::new();
    let result = (|| -> anyhow::Result<()> {
        for (i, p) in poses.iter().enumerate() {
            move_to(&mut world.robot, &p.joints, &c)?;
            keep_fed(&mut world.robot, Duration::from_secs_f64(c.settle_s))?;
            let after = world.clock.now_s();
            match measure(&mut world, &mut source, c.samples_per_pose, after)? {
                Some((q, tracker_from_marker)) => {
                    let mut pair = Pair::new(arm.fk_flange(&q), tracker_from_marker);
                    pair.joints = Some(q);
                    pairs.push(pair);
                }
                None => {
                    missed.push(i + 1);
                    bar.set_message(format!("marker not seen at pose {}", i + 1));
                }
            }
            bar.inc(1);
        }
        move_to(&mut world.robot, &current, &c)
    })();
    bar.finish_and_clear();
    if let Err(e) = result {
        return Err(match world.robot.stop(4.0) {
            Ok(_) => e.context("calibrate collect stopped the robot"),
            Err(stop) => e.context(format!(
                "calibrate collect could not stop the robot either ({stop})"
            )),
        });
    }
    let simulated_robot = world.simulated_robot();
    let _ = world.robot.close();
    drop(client);
    writeln!(
        out,
        "measured {} of {} poses{}",
        pairs.len(),
        poses.len(),
        if missed.is_empty() {
            String::new()
        } else {
            format!("; marker not seen at pose(s) {missed:?}")
        }
    )?;
    if pairs.len() < 3 {
        refuse!(
            "only {} poses measured: check that the tracker sees calibrate.device {:?}",
            pairs.len(),
            c.device
        );
    }

    let noise = NoiseModel {
        tracker_translation_m: c.tracker_noise_m,
        tracker_rotation_rad: c.tracker_noise_rad,
        robot_translation_m: c.robot_noise_m,
        robot_rotation_rad: c.robot_noise_rad,
    };
    let method = c.method;
    let solved = solve(
        &pairs,
        &SolveOptions {
            method,
            noise,
            reject_outliers: true,
        },
    )
    .context("solving the calibration")?;
    crate::calib_cmd::print_report(&mut &mut *out, &solved, pairs.len())?;

    let out_path = match &opts.out {
        Some(p) => p.clone(),
        None => setup.dir.join(&c.out),
    };
    std::fs::write(&out_path, solved.to_file().to_toml_string()?)
        .with_context(|| format!("writing {}", out_path.display()))?;
    writeln!(out, "wrote {}", out_path.display())?;
    if let Some(p) = &c.pairs_csv {
        let path = out_path
            .parent()
            .unwrap_or(Path::new(""))
            .join(Path::new(p).file_name().unwrap_or_default());
        std::fs::write(&path, write_pairs_csv(&pairs, PairsFormat::Joints)?)
            .with_context(|| format!("writing {}", path.display()))?;
        writeln!(
            out,
            "wrote {} (re-solve with: mocomp calibrate solve --pairs {} --robot {})",
            path.display(),
            path.display(),
            setup.file.robot.model
        )?;
    }
    let y_old = setup.base_from_tracker;
    writeln!(
        out,
        "Y against the configured base_from_tracker: {:.2} mm, {:.3}°",
        translation_error(&solved.base_from_tracker, &y_old) * 1e3,
        rotation_error(&solved.base_from_tracker, &y_old).to_degrees()
    )?;
    let s = &setup.file.tracker.simulated;
    if setup.file.tracker.source == crate::run_config::TrackerSource::Simulated && simulated_robot {
        let true_y = match &s.base_from_tracker {
            Some(y) => pose("tracker.simulated.base_from_tracker", y)?,
            None => y_old,
        };
        let true_x = pose(
            "tracker.simulated.flange_from_marker",
            &s.flange_from_marker,
        )?;
        writeln!(
            out,
            "against the simulation's truth: Y {:.3} mm, {:.4}°; X {:.3} mm, {:.4}°",
            translation_error(&solved.base_from_tracker, &true_y) * 1e3,
            rotation_error(&solved.base_from_tracker, &true_y).to_degrees(),
            translation_error(&solved.flange_from_marker, &true_x) * 1e3,
            rotation_error(&solved.flange_from_marker, &true_x).to_degrees()
        )?;
    }
    writeln!(
        out,
        "to use it: set calibration.file = {:?} in the configuration",
        c.out
    )?;
    Ok(())
}
