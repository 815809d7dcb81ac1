//! Calibration collection on the live robot (`mocomp calibrate collect`): runs the calibration
//! planner's poses on the robot, records the tracker's measurement of the flange's marker at each,
//! solves `AX = YB`, and saves the calibration (and the pairs, for `calibrate solve`).

use crate::config::{CollectSection, Setup, TrackerSource};
use crate::frontend::Controls;
use crate::world::World;
use crate::{AppError, Context};
use mocomp_calib::plan::{PlanOptions, TrackerView, plan};
use mocomp_calib::procedure::{self as calibration, Measurement, MoveState, Station, move_state};
use mocomp_calib::{
    Calibration, NoiseModel, Pair, PairsFormat, SolveOptions, solve, write_pairs_csv,
};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{PoseSource, rotation_error, translation_error};
use mocomp_ur::{Robot, RobotFault};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What the collection is doing, for a progress display.
#[derive(Debug, Clone, PartialEq)]
pub enum Progress {
    /// The poses are planned; the collection waits for the operator's go (a console's start).
    Waiting {
        /// How many poses.
        poses: usize,
    },
    /// The poses are planned around `center` (base_from_flange); the arm is about to move.
    Planned {
        /// How many.
        poses: usize,
        /// The centre flange pose.
        center: Isometry3<f64>,
    },
    /// Pose `index` (0-based) is done; `seen` whether the marker was measured there.
    Pose {
        /// Which.
        index: usize,
        /// Whether the marker was seen.
        seen: bool,
    },
}

impl Progress {
    /// What a person should read at this step (before the arm moves, above all), if anything.
    pub fn announcement(&self) -> Option<String> {
        match self {
            Self::Waiting { poses } => Some(format!(
                "{poses} calibration poses planned: press Start in the console (the arm will move)"
            )),
            Self::Planned { poses, center } => Some(format!(
                "{poses} calibration poses around the flange at [{}]; the arm will move: keep the space clear",
                mocomp_geom::text::row(&mocomp_geom::ur_pose_from_iso(center))
            )),
            Self::Pose { .. } => None,
        }
    }
}

/// What the collection measured, solved and saved.
#[derive(Debug, Clone)]
pub struct Collected {
    /// Poses planned.
    pub planned: usize,
    /// The pairs measured.
    pub pairs: Vec<Pair>,
    /// Poses (1-based) where the marker was not seen.
    pub missed: Vec<usize>,
    /// The solution.
    pub solved: Calibration,
    /// Where it was saved.
    pub out: PathBuf,
    /// Where the pairs were saved.
    pub pairs_csv: Option<PathBuf>,
    /// The solved Y against the configured base_from_tracker, m and rad.
    pub y_change: PoseError,
    /// With the simulated world: the errors of Y and X against its truth, (m, rad) each.
    pub against_truth: Option<(PoseError, PoseError)>,
    /// Times the control program, stopped by its watchdog, was started again.
    pub rearmed: usize,
}

/// Restarts of a stopped control program one collection makes by itself, at most.
pub const MAX_REARMS: usize = 3;

/// Rule `CollectionRearm`: whether a collection may start the control program again by itself,
/// `done` restarts already made. Only when the program alone stopped (the arm connected,
/// powered, running, in no safety stop): what a PC that left the program's 50 ms watchdog unfed
/// causes. No patient is under the arm while it calibrates, and the arm only goes on with the
/// sweep the operator started, so losing a 15-pose collection to a 50 ms hiccup helps nobody. A
/// protective or emergency stop, a lost connection or an arm not running is the operator's, as
/// is a program that keeps stopping.
pub fn may_rearm(fault: Option<RobotFault>, done: usize) -> Result<(), String> {
    match fault {
        Some(RobotFault::ProgramStopped) if done < MAX_REARMS => Ok(()),
        Some(RobotFault::ProgramStopped) => Err(format!(
            "the control program stopped {} times: is this PC starving it (real time)?",
            done + 1
        )),
        Some(other) => Err(format!("{other}: the operator's to clear")),
        None => Err("the robot reports no fault".into()),
    }
}

impl Collected {
    /// One line for a front end: how many poses were measured, the residuals, the file.
    pub fn one_line(&self) -> String {
        format!(
            "{} of {} poses measured; residuals {:.3} mm, {:.3}° RMS; saved {}{}",
            self.pairs.len(),
            self.planned,
            self.solved.rms_mm,
            self.solved.rms_deg,
            self.out.display(),
            self.rearm_words()
                .map(|w| format!("; {w}"))
                .unwrap_or_default()
        )
    }

    /// The restarts, in words, if any.
    fn rearm_words(&self) -> Option<String> {
        (self.rearmed > 0).then(|| {
            format!(
                "the control program, stopped by its watchdog, started again {} time(s) (this \
                 PC left it unfed for over 50 ms: see the real-time warning)",
                self.rearmed
            )
        })
    }

    /// The report: what was measured, the calibration's own report, where it was written and
    /// how to use it (`setup` is the one it ran with).
    pub fn text(&self, setup: &Setup) -> String {
        use std::fmt::Write;
        let missed = if self.missed.is_empty() {
            String::new()
        } else {
            format!("; marker not seen at pose(s) {:?}", self.missed)
        };
        let mut s = format!(
            "measured {} of {} poses{missed}\n{}wrote {}\n",
            self.pairs.len(),
            self.planned,
            self.solved,
            self.out.display()
        );
        if let Some(w) = self.rearm_words() {
            let _ = writeln!(s, "note: {w}");
        }
        // Writing to a String cannot fail.
        if let Some(p) = &self.pairs_csv {
            let _ = writeln!(
                s,
                "wrote {} (re-solve with: mocomp calibrate solve --pairs {} --robot {})",
                p.display(),
                p.display(),
                setup.model
            );
        }
        let _ = writeln!(
            s,
            "Y against the configured base_from_tracker: {:.2} mm, {:.3}°",
            self.y_change.0 * 1e3,
            self.y_change.1.to_degrees()
        );
        if let Some((y, x)) = self.against_truth {
            let _ = writeln!(
                s,
                "against the simulation's truth: Y {:.3} mm, {:.4}°; X {:.3} mm, {:.4}°",
                y.0 * 1e3,
                y.1.to_degrees(),
                x.0 * 1e3,
                x.1.to_degrees()
            );
        }
        let _ = writeln!(
            s,
            "to use it: set calibration.file = {:?} in the configuration",
            setup.file.calibrate.out
        );
        s
    }
}

/// A pose's error: translation (m) and rotation (rad).
pub type PoseError = (f64, f64);

/// The live robot and tracker as a calibration station, on the wall clock.
struct Live<'a> {
    world: &'a mut World,
    source: &'a mut dyn PoseSource,
    c: &'a CollectSection,
    /// A front end's stop, checked while the station waits.
    controls: Option<&'a Controls>,
    /// Restarts of the control program so far ([`may_rearm`]).
    rearmed: usize,
}

impl Live<'_> {
    /// Feeds the program's watchdog while the station waits, and ends the collection when a
    /// front end asked to stop (the caller then stops the robot).
    fn feed(&mut self) -> Result<(), AppError> {
        if self.controls.is_some_and(Controls::stop_requested) {
            refuse!("stopped by the operator");
        }
        self.world
            .robot
            .keep_alive()
            .what(|| "keeping the robot's program running")
    }

    /// Starts the control program again where [`may_rearm`] allows it; where it does not, why
    /// (the caller then stops, saying so).
    fn rearm(&mut self) -> Result<Option<String>, AppError> {
        let fault = self.world.robot.state().and_then(|s| s.fault());
        if let Err(why) = may_rearm(fault, self.rearmed) {
            return Ok(Some(why));
        }
        self.world
            .robot
            .restart_program()
            .what(|| "starting the control program its watchdog stopped")?;
        self.rearmed += 1;
        Ok(None)
    }

    /// `movej` to `q`, starting a control program its watchdog stopped first.
    fn send_move(&mut self, q: &[f64; 6]) -> Result<i32, AppError> {
        let c = self.c;
        match self
            .world
            .robot
            .move_joints(q, c.joint_speed_rad_s, c.joint_accel_rad_s2)
        {
            Ok(seq) => Ok(seq),
            // Refused with no fault (a bad target): nothing to restart, the refusal is the why.
            Err(e) if self.world.robot.state().and_then(|s| s.fault()).is_none() => {
                Err(AppError::failed("a calibration move", e))
            }
            Err(e) => match self.rearm()? {
                None => self
                    .world
                    .robot
                    .move_joints(q, c.joint_speed_rad_s, c.joint_accel_rad_s2)
                    .what(|| format!("a calibration move (after {e})")),
                Some(why) => Err(AppError::failed(format!("a calibration move: {why}"), e)),
            },
        }
    }
}

impl Station for Live<'_> {
    type Error = AppError;

    fn move_to(&mut self, q: &[f64; 6]) -> Result<(), AppError> {
        let c = self.c;
        let mut seq = self.send_move(q)?;
        let mut start = Instant::now();
        loop {
            if let Some(s) = self.world.robot.state() {
                if let Some(f) = s.fault() {
                    if let Err(why) = may_rearm(Some(f), self.rearmed) {
                        refuse!("the robot stopped during a calibration move: {why}");
                    }
                    // The move again from where the arm stopped, on the program started anew.
                    seq = self.send_move(q)?;
                    start = Instant::now();
                    continue;
                }
                match move_state(&s, q, seq) {
                    MoveState::Arrived => return Ok(()),
                    MoveState::Away => refuse!("a calibration move ended away from its target"),
                    MoveState::Moving => {}
                }
            }
            if start.elapsed().as_secs_f64() > c.move_timeout_s {
                refuse!(
                    "a calibration move did not arrive within calibrate.move_timeout_s = {} s",
                    c.move_timeout_s
                );
            }
            self.feed()?;
            std::thread::sleep(Duration::from_millis(4));
        }
    }

    fn settle(&mut self, seconds: f64) -> Result<(), AppError> {
        let end = Instant::now() + Duration::from_secs_f64(seconds);
        while Instant::now() < end {
            self.feed()?;
            std::thread::sleep(Duration::from_millis(8));
        }
        Ok(())
    }

    /// The joints are averaged over the samples' time; a marker unseen for 3 s is not seen.
    fn measure(&mut self, n: usize) -> Result<Option<Measurement>, AppError> {
        let start = Instant::now();
        let mut samples = Vec::with_capacity(n);
        let mut qs = Vec::new();
        // Polled faster than the tracker sends: each sample counts once.
        let mut last = self.world.clock.now_s();
        while samples.len() < n {
            if start.elapsed() > Duration::from_secs(3) {
                return Ok(None);
            }
            if let Some(s) = self.source.latest()
                && s.valid
                && s.acquired_s > last
            {
                last = s.acquired_s;
                samples.push(s.tracker_from_marker);
                if let Some(r) = self.world.robot.state() {
                    qs.push(r.actual_q);
                }
            }
            self.feed()?;
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
}

/// Runs the collection on `setup`'s world, solves, and saves the calibration to `out` (default:
/// `calibrate.out` beside the configuration) with the pairs beside it. `notice` is told what
/// starts; `progress`, how the collection goes. With `controls` (a console), the arm moves only
/// after the operator's go ([`Controls::request_start`]), and the operator's stop ends the
/// collection and stops the robot.
pub fn collect(
    setup: &Setup,
    out: Option<&Path>,
    notice: &mut dyn Write,
    progress: &mut dyn FnMut(Progress),
    controls: Option<&Controls>,
) -> Result<Collected, AppError> {
    let c = setup.file.calibrate.clone();
    let arm = setup.arm;
    let q0 = setup.initial_joints()?;
    setup.needs_igtl_tracker("calibrate collect")?;
    let mut world = World::connect_feeding_watchdog(setup, q0, notice)?;
    let client = world.client(setup, &c.device);
    let mut source = client.pose_source();

    let current = current_joints(&world)?;
    let (poses, center) = plan_poses(setup, &c, &mut world, current)?;
    if let Some(controls) = controls {
        wait_for_go(&mut world, controls, progress, poses.len())?;
    }
    progress(Progress::Planned {
        poses: poses.len(),
        center,
    });

    let mut station = Live {
        world: &mut world,
        source: &mut source,
        c: &c,
        controls,
        rearmed: 0,
    };
    let result = calibration::collect(
        &mut station,
        &arm,
        &poses,
        &current,
        c.settle_s,
        c.samples_per_pose,
        &mut |index, seen| progress(Progress::Pose { index, seen }),
    );
    let rearmed = station.rearmed;
    let calibration::Collection { pairs, missed } = match result {
        Ok(got) => got,
        Err(e) => {
            let what = match world.robot.stop(4.0) {
                Ok(_) => "calibrate collect stopped the robot".to_string(),
                Err(stop) => {
                    format!("calibrate collect could not stop the robot either ({stop})")
                }
            };
            mocomp_rt::leave_realtime().ok();
            return Err(AppError::failed(what, e));
        }
    };
    let simulated_robot = world.simulated_robot();
    // The arm is back and still: a failed close changes nothing.
    world.robot.close().ok();
    drop(client);
    // The solve that follows is CPU work that must not hold a core at real-time priority.
    mocomp_rt::leave_realtime().ok();
    if pairs.len() < 3 {
        refuse!(
            "only {} of {} poses measured (marker not seen at pose(s) {missed:?}): check that \
             the tracker sees calibrate.device {:?}",
            pairs.len(),
            poses.len(),
            c.device
        );
    }

    let (solved, out_path, pairs_csv) = solve_and_save(setup, &c, &pairs, out)?;
    let (y_change, against_truth) = against(setup, &solved, simulated_robot);
    Ok(Collected {
        planned: poses.len(),
        missed,
        y_change,
        pairs,
        solved,
        out: out_path,
        pairs_csv,
        against_truth,
        rearmed,
    })
}

/// Where the robot is (the run starts and ends here), within 5 s.
fn current_joints(world: &World) -> Result<[f64; 6], AppError> {
    let t0 = Instant::now();
    loop {
        if let Some(s) = world.robot.state() {
            return Ok(s.actual_q);
        }
        if t0.elapsed() > Duration::from_secs(5) {
            refuse!("no robot state within 5 s");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The calibration poses about the configured centre (else where the flange is), planned while
/// the robot's program is kept running.
fn plan_poses(
    setup: &Setup,
    c: &CollectSection,
    world: &mut World,
    current: [f64; 6],
) -> Result<(Vec<mocomp_calib::plan::PlannedPose>, Isometry3<f64>), AppError> {
    let arm = setup.arm;
    let center = match &c.center {
        Some(p) => p.iso(),
        None => arm.fk_flange(&current),
    };
    let mut o = PlanOptions::new(c.poses, center, current);
    o.rotation_range_rad = (c.min_rotation_rad, c.max_rotation_rad);
    o.translation_spread_m = c.spread_m;
    o.flange_from_marker = c.flange_from_marker_guess.iso();
    o.tracker = c
        .check_view
        .then(|| TrackerView::typical(setup.base_from_tracker));
    // Planning takes long in a debug build or on a busy machine: the running program's watchdog
    // is fed meanwhile.
    let poses = world
        .robot
        .keep_alive_while(|| plan(&arm, &o))
        .what(|| "keeping the robot's program running while planning")?
        .what(|| "planning the calibration poses")?;
    Ok((poses, center))
}

/// Waits for the operator's go, the robot's program fed meanwhile; the operator's stop refuses.
fn wait_for_go(
    world: &mut World,
    controls: &Controls,
    progress: &mut dyn FnMut(Progress),
    poses: usize,
) -> Result<(), AppError> {
    progress(Progress::Waiting { poses });
    while !controls.start_requested() {
        if controls.stop_requested() {
            refuse!("stopped by the operator before the arm moved");
        }
        world
            .robot
            .keep_alive()
            .what(|| "keeping the robot's program running while waiting for the go")?;
        std::thread::sleep(Duration::from_millis(10));
    }
    Ok(())
}

/// Solves the pairs and saves the calibration to `out` (default: `calibrate.out` beside the
/// configuration), with the pairs beside it when asked.
fn solve_and_save(
    setup: &Setup,
    c: &CollectSection,
    pairs: &[Pair],
    out: Option<&Path>,
) -> Result<(Calibration, PathBuf, Option<PathBuf>), AppError> {
    let noise = NoiseModel {
        tracker_translation_m: c.tracker_noise_m,
        tracker_rotation_rad: c.tracker_noise_rad,
        robot_translation_m: c.robot_noise_m,
        robot_rotation_rad: c.robot_noise_rad,
    };
    let solved = solve(
        pairs,
        &SolveOptions {
            method: c.method,
            noise,
            reject_outliers: true,
        },
    )
    .what(|| "solving the calibration")?;

    let out_path = out.map_or_else(|| setup.dir.join(&c.out), Path::to_path_buf);
    let text = solved
        .to_file()
        .to_toml_string()
        .what(|| "writing the calibration")?;
    std::fs::write(&out_path, text).what(|| format!("writing {}", out_path.display()))?;
    let pairs_csv = match &c.pairs_csv {
        Some(p) => {
            let path = out_path
                .parent()
                .unwrap_or(Path::new(""))
                .join(Path::new(p).file_name().unwrap_or_default());
            let text = write_pairs_csv(pairs, PairsFormat::Joints).what(|| "writing the pairs")?;
            std::fs::write(&path, text).what(|| format!("writing {}", path.display()))?;
            Some(path)
        }
        None => None,
    };
    Ok((solved, out_path, pairs_csv))
}

/// The solved Y against the configured one, and, in the simulated world, Y and X against its
/// truth.
fn against(
    setup: &Setup,
    solved: &Calibration,
    simulated_robot: bool,
) -> (PoseError, Option<(PoseError, PoseError)>) {
    let err =
        |a: &Isometry3<f64>, b: &Isometry3<f64>| (translation_error(a, b), rotation_error(a, b));
    let y_old = setup.base_from_tracker;
    let s = &setup.file.tracker.simulated;
    let against_truth = (setup.file.tracker.source == TrackerSource::Simulated && simulated_robot)
        .then(|| {
            let true_y = s.base_from_tracker.map_or(y_old, |p| p.iso());
            (
                err(&solved.base_from_tracker, &true_y),
                err(&solved.flange_from_marker, &s.flange_from_marker.iso()),
            )
        });
    (err(&solved.base_from_tracker, &y_old), against_truth)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::{Live, MAX_REARMS, may_rearm};
    use crate::config::{Config, Setup};
    use crate::world::World;
    use mocomp_calib::procedure::Station;
    use mocomp_ur::{Robot, RobotFault, RobotMode, SafetyMode};
    use std::time::{Duration, Instant};

    /// On the built-in world (the simulated UR3e speaking RTDE on loopback): a program stopped
    /// under a calibration move is started again and the move made, until the rule says no more.
    #[test]
    fn a_stopped_program_is_started_again_for_the_move_until_it_keeps_stopping() {
        let mut file = Config::default();
        // An address of its own (a taken one moves to the next free).
        file.robot.host = "127.0.0.151".into();
        let setup = Setup::new(file, None, std::path::PathBuf::from(".")).unwrap();
        let q0 = setup.initial_joints().unwrap();
        let mut world = World::connect(&setup, q0, &mut std::io::sink(), None).unwrap();
        let client = world.client(&setup, &setup.file.tracker.device);
        let mut source = client.pose_source();
        let sim = world.sim.clone().expect("the built-in world");
        let c = setup.file.calibrate.clone();
        let mut station = Live {
            world: &mut world,
            source: &mut source,
            c: &c,
            controls: None,
            rearmed: 0,
        };
        let mut aside = q0;
        aside[0] += 0.05;
        let mut refused = None;
        for k in 0..=MAX_REARMS {
            sim.with(|ctl| ctl.stop_program("stopped by the test".into()));
            let t = Instant::now();
            while !station
                .world
                .robot
                .state()
                .is_some_and(|s| s.fault() == Some(RobotFault::ProgramStopped))
            {
                assert!(
                    t.elapsed() < mocomp_testkit::HUNG,
                    "the program never stopped"
                );
                std::thread::sleep(Duration::from_millis(2));
            }
            let target = if k % 2 == 0 { aside } else { q0 };
            match station.move_to(&target) {
                Ok(()) => {
                    let q = station.world.robot.state().unwrap().actual_q;
                    assert!((q[0] - target[0]).abs() < 1e-3, "arrived: {q:?}");
                }
                Err(e) => {
                    refused = Some(crate::in_full(&e));
                    break;
                }
            }
        }
        // Each stop restarted once (a busy machine's own watchdog stops only bring the end
        // nearer), and the one past the rule's count refused by name.
        let refused = refused.expect("refused once the program kept stopping");
        assert_eq!(station.rearmed, MAX_REARMS, "{refused}");
        assert!(refused.contains("stopped 4 times"), "{refused}");
    }

    /// `CollectionRearm`: a program its watchdog stopped is started again, a few times; every
    /// other stop is the operator's.
    #[test]
    fn a_collection_restarts_only_a_stopped_program_and_only_a_few_times() {
        for done in 0..MAX_REARMS {
            assert_eq!(may_rearm(Some(RobotFault::ProgramStopped), done), Ok(()));
        }
        let again = may_rearm(Some(RobotFault::ProgramStopped), MAX_REARMS).unwrap_err();
        assert!(again.contains("stopped 4 times"), "{again}");
        for other in [
            RobotFault::ProtectiveStop,
            RobotFault::EmergencyStop,
            RobotFault::Disconnected,
            RobotFault::Safety(SafetyMode::Violation),
            RobotFault::NotRunning(RobotMode::PowerOff),
        ] {
            let why = may_rearm(Some(other), 0).unwrap_err();
            assert!(why.contains("operator"), "{other}: {why}");
        }
        assert!(may_rearm(None, 0).is_err());
    }
}
