#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! The safety filter and the supervisor's reactions on a head that moves towards the coil, away
//! from it, too fast to follow, and out of view for a moment: an in-memory robot (a perfect
//! servo) and a scripted 60 Hz tracker (`mocomp_testkit::mem`), no sockets, time stepped by the
//! test. The coil's true clearance is judged against the true head at the time each command
//! acts (the servo's lag after it is sent), where the loop aims it.

mod common;

use common::mem::{PERIOD, coil_on_head_joints};
use mocomp_control::{Compensator, CycleRecord, Event, LoopConfig, Mode, Reason};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_kin::{Arm, Model};
use mocomp_testkit::SplitMix64;
use mocomp_testkit::mem::{MemRobot, ScriptedPoses};
use mocomp_testkit::scene::{base_from_tracker, flange_from_coil, head_from_coil_goal, head_rest};

type Motion = fn(f64) -> Option<Isometry3<f64>>;

struct Run {
    records: Vec<CycleRecord>,
    /// The coil's true clearance from the head at the time each command acts, m.
    clearance: Vec<f64>,
}

impl Run {
    fn events(&self) -> Vec<(f64, Event)> {
        self.records
            .iter()
            .filter_map(|r| r.event.map(|e| (r.t, e)))
            .collect()
    }

    /// The least true clearance once tracking (from 0.3 s), m.
    fn least_clearance(&self) -> f64 {
        self.clearance
            .iter()
            .skip(150)
            .copied()
            .fold(f64::INFINITY, f64::min)
    }

    fn holds(&self) -> usize {
        self.events()
            .iter()
            .filter(|(_, e)| matches!(e, Event::Hold(_)))
            .count()
    }
}

/// `base_from_head` at rest, moved by `along_z(t)` metres along the head's z axis (towards the
/// coil, which sits on top of the head facing down).
fn along_z(offset: fn(f64) -> f64) -> impl Fn(f64) -> Isometry3<f64> {
    move |t| head_rest() * Isometry3::translation(0.0, 0.0, offset(t))
}

fn run(motion: Motion, seconds: f64) -> Run {
    run_held(motion, seconds, |_| false)
}

/// [`run`], with the operator holding the loop while `held(t)`.
fn run_held(motion: Motion, seconds: f64, held: fn(f64) -> bool) -> Run {
    run_with(motion, seconds, |t, comp| comp.set_operator_hold(held(t)))
}

/// [`run`], with `before(t, loop)` before each cycle (what the operator and the session ask).
fn run_with(motion: Motion, seconds: f64, before: impl Fn(f64, &mut Compensator)) -> Run {
    run_with_robot(motion, seconds, |t, comp, _| before(t, comp)).0
}

/// [`run_with`], `before` also given the robot (a hand that moves it); returns the robot too.
fn run_with_robot(
    motion: Motion,
    seconds: f64,
    mut before: impl FnMut(f64, &mut Compensator, &mut MemRobot),
) -> (Run, MemRobot) {
    run_with_tracker(motion, seconds, |t, comp, robot, _| before(t, comp, robot))
}

/// [`run_with_robot`], `before` also given the tracker (its reader failing, its samples lost).
fn run_with_tracker(
    motion: Motion,
    seconds: f64,
    mut before: impl FnMut(f64, &mut Compensator, &mut MemRobot, &mut ScriptedPoses),
) -> (Run, MemRobot) {
    let arm = Arm::new(Model::Ur3e);
    let cfg = LoopConfig::new(
        base_from_tracker(),
        flange_from_coil(),
        head_from_coil_goal(),
        PERIOD,
    );
    let (head, coil) = (cfg.head.clone(), cfg.coil.clone());
    let q0 = coil_on_head_joints(&arm);
    let mut comp = Compensator::new(cfg, arm, PERIOD);
    let mut robot = MemRobot::at(q0, arm.fk(&q0), PERIOD);
    let tracker_from_base = base_from_tracker().inverse();
    // A real tracker's noise (0.05 mm per axis, seeded by the sample time): a noiseless stream
    // would be a frozen one to the loop.
    let noisy = move |t: f64| {
        motion(t).map(|h| {
            let mut g = SplitMix64((t * 1e6).round() as u64);
            let mut n = || (g.next_f64() - 0.5) * 1.7e-4;
            let mut p = tracker_from_base * h;
            p.translation.vector += Vector3::new(n(), n(), n());
            p
        })
    };
    let mut poses = ScriptedPoses::new(60.0, 0.02, Box::new(noisy));
    let mut out = Run {
        records: Vec::new(),
        clearance: Vec::new(),
    };
    let n = (seconds / PERIOD).round() as usize;
    for k in 0..n {
        let t = k as f64 * PERIOD;
        robot.tick(t);
        poses.now = t;
        before(t, &mut comp, &mut robot, &mut poses);
        let rec = comp.cycle(t, &mut robot, &mut poses);
        let coil_pose = arm.fk_flange(&rec.q_command) * flange_from_coil();
        let acts = if rec.horizon_s > 0.0 {
            t + rec.horizon_s - rec.sample_age_s
        } else {
            t
        };
        // The head where it truly is when the command acts (at rest when out of view).
        let true_head = motion(acts).unwrap_or_else(head_rest);
        out.clearance
            .push(coil.distance(&head, &(true_head.inverse() * coil_pose)));
        out.records.push(rec);
    }
    (out, robot)
}

/// Speed ramps of the moves, s: a head reaching 100 mm/s in 0.3 s accelerates at up to
/// 0.5 m/s², more than the patient studies' fast nods (0.36 m/s²).
const RAMP_S: f64 = 0.3;

/// A smooth move of `distance` m starting at 0.5 s, at `speed` m/s (cosine speed ramps).
fn ramp(t: f64, distance: f64, speed: f64) -> f64 {
    let cruise = (distance.abs() / speed - RAMP_S).max(0.0);
    let s = (t - 0.5).max(0.0);
    let v = |u: f64| -> f64 {
        if u < RAMP_S {
            0.5 * (1.0 - (std::f64::consts::PI * u / RAMP_S).cos())
        } else if u < RAMP_S + cruise {
            1.0
        } else if u < 2.0 * RAMP_S + cruise {
            0.5 * (1.0 + (std::f64::consts::PI * (u - RAMP_S - cruise) / RAMP_S).cos())
        } else {
            0.0
        }
    };
    // Integrate the speed profile (fine steps; tests only).
    let steps = (s / 1e-4).ceil() as usize;
    let du = if steps > 0 { s / steps as f64 } else { 0.0 };
    let travelled: f64 = (0..steps).map(|i| v((i as f64 + 0.5) * du) * du).sum();
    distance.signum() * speed * travelled
}

/// The coil's true clearance at the time each command acts stays within 2.5 mm of the goal's 3 mm
/// once tracking (from 0.3 s).
fn assert_keeps_pace(r: &Run) {
    for (rec, c) in r.records.iter().zip(&r.clearance).skip(150) {
        assert!(
            (0.0005..0.0055).contains(c),
            "at {:.3} s the coil is {:.2} mm from the head",
            rec.t,
            c * 1e3
        );
    }
}

fn towards(t: f64) -> Option<Isometry3<f64>> {
    Some(along_z(|t| ramp(t, 0.05, 0.1))(t))
}

fn away(t: f64) -> Option<Isometry3<f64>> {
    Some(along_z(|t| ramp(t, -0.05, 0.1))(t))
}

#[test]
fn a_head_moving_into_the_coil_pushes_it_back_as_fast_without_a_hold() {
    let r = run(towards, 2.0);
    assert_eq!(r.holds(), 0, "{:?}", r.events());
    let least = r.least_clearance();
    assert!(least > 0.0, "the coil entered the head: {least} m");
    // The coil keeps pace: at the time each command acts it is within 2.5 mm of its goal's 3 mm
    // above the scalp, all the way (a held coil would be pushed 50 mm in).
    assert_keeps_pace(&r);
    // And ends on its goal above the moved head.
    let end = r.records.last().unwrap();
    assert_eq!(end.mode, Mode::Tracking);
    assert!(end.deviation.0 < 1e-3, "{:?}", end.deviation);
}

#[test]
fn a_head_moving_away_is_followed_without_a_hold_or_a_retreat() {
    let r = run(away, 2.0);
    assert_eq!(r.holds(), 0, "{:?}", r.events());
    assert!(
        !r.events()
            .iter()
            .any(|(_, e)| matches!(e, Event::Retreat(_))),
        "{:?}",
        r.events()
    );
    assert!(
        r.records
            .iter()
            .skip(150)
            .all(|rec| rec.mode == Mode::Tracking)
    );
    assert_keeps_pace(&r);
    let least = r.least_clearance();
    assert!(least > 0.0, "{least}");
}

fn too_fast(t: f64) -> Option<Isometry3<f64>> {
    // 100 mm towards the coil at 300 mm/s: twice max_head_speed_m_s.
    Some(along_z(|t| ramp(t, 0.1, 0.3))(t))
}

#[test]
fn a_head_too_fast_makes_the_coil_retreat_then_come_back() {
    let r = run(too_fast, 2.5);
    let ev = r.events();
    assert!(
        ev.iter()
            .any(|(_, e)| matches!(e, Event::Retreat(Reason::HeadTooFast(..)))),
        "{ev:?}"
    );
    assert_eq!(r.holds(), 0, "{ev:?}");
    let furthest = r.records.iter().map(|x| x.standoff_m).fold(0.0, f64::max);
    let p = mocomp_control::LoopParams::default();
    assert!(furthest >= p.retreat_distance_m, "{furthest}");
    // Three times the patient studies' fastest head, reaching it at 1.6 m/s²: before the
    // prediction has its acceleration the coil may dip into the scalp's give, never deeper.
    let least = r.least_clearance();
    assert!(least > -p.coil_contact_tolerance_m, "{least}");
    // Back on the goal once the head has stopped (at about 1.13 s).
    let end = r.records.last().unwrap();
    assert_eq!(end.mode, Mode::Tracking);
    assert!(end.standoff_m < 1e-6 && end.deviation.0 < 1e-3, "{end:?}");
}

fn blinking(t: f64) -> Option<Isometry3<f64>> {
    // A slow sway, out of view from 1.0 to 1.1 s.
    if (1.0..1.1).contains(&t) {
        return None;
    }
    let s = (3.0 * t).sin();
    Some(head_rest() * Isometry3::new(Vector3::new(0.01 * s, 0.0, 0.0), Vector3::zeros()))
}

#[test]
fn a_short_dropout_is_coasted_with_a_growing_margin_and_no_hold() {
    let r = run(blinking, 1.6);
    let ev = r.events();
    assert!(
        ev.iter()
            .any(|(t, e)| matches!(e, Event::Coasting(_)) && (1.0..1.1).contains(t)),
        "{ev:?}"
    );
    assert_eq!(r.holds(), 0, "{ev:?}");
    let required = |from: f64, to: f64| {
        r.records
            .iter()
            .filter(|x| x.t >= from && x.t < to)
            .map(|x| x.required_m)
            .fold(0.0, f64::max)
    };
    let before = required(0.8, 0.98);
    let during = required(1.0, 1.15);
    assert!(during > 2.0 * before, "{before} → {during}");
    assert!(
        r.records
            .iter()
            .filter(|x| x.t > 1.05 && x.t < 1.11)
            .all(|x| x.coasting && x.mode == Mode::Tracking)
    );
    let least = r.least_clearance();
    assert!(least > 0.0, "{least}");
}

fn dip(t: f64) -> Option<Isometry3<f64>> {
    // The head sinks 15 mm away from the coil and comes back, between 1 and 2 s.
    Some(along_z(|t| {
        if (1.0..2.0).contains(&t) {
            -0.0075 * (1.0 - (2.0 * std::f64::consts::PI * (t - 1.0)).cos())
        } else {
            0.0
        }
    })(t))
}

/// The largest joint motion between consecutive commands in `[from, to)`, rad.
fn largest_step(r: &Run, from: f64, to: f64) -> f64 {
    r.records
        .windows(2)
        .filter(|w| w[0].t >= from && w[1].t < to)
        .map(|w| {
            (0..6).fold(0.0f64, |m, j| {
                m.max((w[1].q_command[j] - w[0].q_command[j]).abs())
            })
        })
        .fold(0.0, f64::max)
}

#[test]
fn the_operators_hold_stops_the_coil_and_resume_brings_it_back_to_the_goal() {
    let r = run_held(dip, 3.5, |t| (1.0..2.2).contains(&t));
    let ev = r.events();
    let held_at = ev
        .iter()
        .find(|(_, e)| *e == Event::Hold(Reason::Operator))
        .map(|(t, _)| *t);
    assert!(held_at.is_some_and(|t| (1.0..1.01).contains(&t)), "{ev:?}");
    // Held: after decelerating (well under 0.3 s) the command stands still while the head moves.
    assert!(
        largest_step(&r, 1.3, 2.2) < 1e-9,
        "{}",
        largest_step(&r, 1.3, 2.2)
    );
    let during: Vec<_> = r
        .records
        .iter()
        .filter(|x| (1.3..2.2).contains(&x.t))
        .collect();
    assert!(
        during
            .iter()
            .all(|x| x.mode == Mode::Holding(Reason::Operator))
    );
    // The head sank away meanwhile: the coil is off its goal.
    assert!(during.iter().any(|x| x.deviation.0 > 5e-3));
    // Never closer than the head allows, held or not.
    assert!(r.least_clearance() > 0.0, "{}", r.least_clearance());
    // Resumed: back on the goal and tracking by the end.
    assert!(
        ev.iter()
            .any(|(t, e)| *t >= 2.2 && matches!(e, Event::Resume)),
        "{ev:?}"
    );
    let end = r.records.last().unwrap();
    assert_eq!(end.mode, Mode::Tracking, "{ev:?}");
    assert!(end.deviation.0 < 1e-3, "{:?}", end.deviation);
}

fn at_rest(_: f64) -> Option<Isometry3<f64>> {
    Some(head_rest())
}

#[test]
fn an_invalid_calibration_holds_with_its_offset_before_the_operators_hold_and_ends_when_cleared() {
    let offset = (0.003, 1f64.to_radians());
    let r = run_with(at_rest, 3.0, |t, comp| {
        comp.set_calibration_invalid((1.0..2.0).contains(&t).then_some(offset));
        // The operator holds too, from 1.5 s to 1.8 s: the calibration's reason stays shown.
        comp.set_operator_hold((1.5..1.8).contains(&t));
    });
    let ev = r.events();
    let holds: Vec<_> = ev
        .iter()
        .filter(|(_, e)| matches!(e, Event::Hold(_)))
        .collect();
    assert_eq!(
        holds,
        [&(
            1.0,
            Event::Hold(Reason::CalibrationInvalid(offset.0, offset.1))
        )],
        "{ev:?}"
    );
    assert!(
        r.records
            .iter()
            .filter(|x| (1.0..2.0).contains(&x.t))
            .all(|x| x.mode == Mode::Holding(Reason::CalibrationInvalid(offset.0, offset.1)))
    );
    // Before and after, on target: the coil's own error is what the gate judges, and it is
    // small where the flange's is.
    let before = r.records.iter().rfind(|x| x.t < 1.0).unwrap();
    assert_eq!(before.mode, Mode::Tracking);
    assert!(before.coil_error.0 < 1e-3, "{:?}", before.coil_error);
    let end = r.records.last().unwrap();
    assert_eq!(end.mode, Mode::Tracking, "{ev:?}");
    assert!(
        end.coil_error.0 < 1e-3 && end.coil_error.1 < 0.01,
        "{:?}",
        end.coil_error
    );
    // The coil on the head (what a pulse's record keeps) is the pose whose distance from the
    // goal that error is: the same head, the same frames.
    for x in [before, end] {
        let coil = x.coil_now.unwrap();
        let goal = x.head_from_coil_goal;
        let d = (coil.translation.vector - goal.translation.vector).norm();
        let a = coil.rotation.angle_to(&goal.rotation);
        assert!((d - x.coil_error.0).abs() < 1e-9, "{d} {:?}", x.coil_error);
        assert!((a - x.coil_error.1).abs() < 1e-9, "{a} {:?}", x.coil_error);
    }
}

/// Gentle nods about the head's x axis and a sway along y (a seated patient's).
fn nodding(t: f64) -> Option<Isometry3<f64>> {
    let w = 2.0 * std::f64::consts::PI * 0.3;
    Some(
        head_rest()
            * Isometry3::new(
                Vector3::new(0.0, 0.004 * (w * t).sin(), 0.0),
                Vector3::x() * 0.02 * (w * t).sin(),
            ),
    )
}

/// The goal moved sideways by `dx` m in the coil's frame and tilted as the normal of a 10 cm
/// radius scalp turns over that distance (a neighbour on a mapping grid).
fn neighbour(dx: f64) -> Isometry3<f64> {
    head_from_coil_goal() * Isometry3::new(Vector3::new(dx, 0.0, -0.002), Vector3::y() * (dx / 0.1))
}

fn once_at(t: f64, at: f64) -> bool {
    (t - at).abs() < PERIOD / 2.0
}

#[test]
fn a_neighbouring_target_on_a_nodding_head_is_reached_by_a_path_without_a_hold() {
    let r = run_with(nodding, 5.0, |t, comp| {
        if once_at(t, 1.0) {
            comp.set_goal(&neighbour(0.01)).unwrap();
        }
    });
    let ev = r.events();
    // Leaving the old target the coil backs out along its own axis, which is 1 cm off the new
    // goal's: that is no approach from the side.
    assert_eq!(r.holds(), 0, "{ev:?}");
    let approaching: Vec<_> = r
        .records
        .iter()
        .filter(|x| x.mode == Mode::Approaching)
        .collect();
    assert!(!approaching.is_empty() && approaching.iter().all(|x| x.path.is_some()));
    let end = r.records.last().unwrap();
    assert_eq!(end.mode, Mode::Tracking, "{ev:?}");
    assert!(end.coil_error.0 < 1e-3, "{:?}", end.coil_error);
    assert!(r.least_clearance() > 0.0);
}

#[test]
fn a_goal_changed_while_approaching_gets_a_new_path_never_a_straight_line() {
    let r = run_with(at_rest, 6.0, |t, comp| {
        if once_at(t, 1.0) {
            comp.set_goal(&neighbour(0.01)).unwrap();
        }
        // Halfway along that path, another.
        if once_at(t, 1.8) {
            comp.set_goal(&neighbour(-0.01)).unwrap();
        }
    });
    let ev = r.events();
    let approaching: Vec<_> = r
        .records
        .iter()
        .filter(|x| x.mode == Mode::Approaching)
        .collect();
    assert!(
        approaching.iter().all(|x| x.path.is_some()),
        "approaching without a path: {ev:?}"
    );
    // The second path starts from where the first was left, at its start: a new plan.
    let second = r
        .records
        .iter()
        .find(|x| x.t > 1.8 && x.mode == Mode::Approaching)
        .unwrap();
    assert!(second.path.unwrap().0 < 1e-3, "{:?}", second.path);
    let end = r.records.last().unwrap();
    assert_eq!(end.mode, Mode::Tracking, "{ev:?}");
    assert!(end.coil_error.0 < 1e-3, "{:?}", end.coil_error);
    assert!(r.least_clearance() > 0.0);
}

#[test]
fn free_drive_yields_to_the_hand_and_hands_back_from_where_the_hand_left_the_coil() {
    let mut q_hand = [0.0; 6];
    let (run, robot) = run_with_robot(at_rest, 7.0, |t, comp, robot| {
        if once_at(t, 1.0) {
            comp.set_freedrive(true);
        }
        if (1.0..2.0).contains(&t) {
            // The hand: the base joint turned by 0.15 rad and the coil lifted off, over a second.
            q_hand = robot.state.actual_q;
            q_hand[0] += 0.15 * PERIOD;
            q_hand[1] -= 0.1 * PERIOD;
            robot.state.actual_q = q_hand;
        }
        if once_at(t, 2.0) {
            comp.set_freedrive(false);
        }
    });
    let records = run.records;
    let guided: Vec<_> = records
        .iter()
        .filter(|r| (1.0..2.0).contains(&r.t))
        .collect();
    // While guided: held for the hand, nothing commanded but free-drive (the command is the arm
    // itself), the head still estimated.
    assert!(
        guided
            .iter()
            .all(|r| r.mode == Mode::Holding(Reason::HandGuided))
    );
    assert!(
        guided
            .iter()
            .all(|r| r.q_command == r.q_actual && r.head_now.is_some() && r.sample_age_s < 0.1)
    );
    assert!(robot.freedrives >= 499, "{}", robot.freedrives);
    let moved = guided.last().unwrap().coil_error.0;
    assert!(
        moved > 0.02,
        "the hand moved the coil {moved} m off its goal"
    );
    // Handed back: the first command starts where the hand left the arm (no jump back to the
    // last command before free-drive), and the goal is reached by a path.
    let back = records.iter().find(|r| r.t >= 2.0).unwrap();
    let jump = (0..6).fold(0.0f64, |m, j| m.max((back.q_command[j] - q_hand[j]).abs()));
    assert!(jump < 0.01, "{jump} rad");
    assert!(
        records
            .iter()
            .any(|r| r.t > 2.0 && r.mode == Mode::Approaching && r.path.is_some())
    );
    let end = records.last().unwrap();
    assert_eq!(end.mode, Mode::Tracking);
    assert!(end.coil_error.0 < 1e-3, "{:?}", end.coil_error);
}

fn push_in(t: f64) -> Option<Isometry3<f64>> {
    // 40 mm into the coil at 100 mm/s.
    Some(along_z(|t| ramp(t - 0.5, 0.04, 0.1))(t))
}

#[test]
fn a_held_coil_gives_way_to_a_head_moving_into_it_and_holds_again() {
    let r = run_held(push_in, 2.5, |t| t >= 0.6);
    let ev = r.events();
    assert!(
        ev.iter()
            .any(|(_, e)| matches!(e, Event::Retreat(Reason::CoilCollision(_)))),
        "{ev:?}"
    );
    // The patient never gives way: at most the scalp's give, which the tracking loop allows too.
    let p = mocomp_control::LoopParams::default();
    let least = r.least_clearance();
    assert!(least > -p.coil_contact_tolerance_m, "{least}");
    // One give-way per approach of the head, not a hold and a retreat every other cycle.
    let switches = ev
        .iter()
        .filter(|(_, e)| matches!(e, Event::Retreat(_) | Event::Hold(_)))
        .count();
    assert!(switches <= 8, "{ev:?}");
    // Once the head stops (at about 1.4 s) the coil holds again, further out than the goal by
    // more than the scalp's give (not back at the goal, not against the scalp): how much
    // further is the retreat's overshoot, which the command's acceleration budget sets (10.1 mm
    // at 60 rad/s², 7.4 at 120, with the goal at 3).
    let end = r.records.last().unwrap();
    assert_eq!(end.mode, Mode::Holding(Reason::Operator), "{ev:?}");
    assert!(largest_step(&r, 2.2, 2.5) < 1e-9);
    // (The run starts with the coil on its goal.)
    let (goal_clearance, last_clearance) = (r.clearance[0], *r.clearance.last().unwrap());
    assert!(
        last_clearance > goal_clearance + p.coil_contact_tolerance_m,
        "{last_clearance} m, the goal's {goal_clearance} m"
    );
}

fn lost_while_moving(t: f64) -> Option<Isometry3<f64>> {
    // Sideways at 50 mm/s from 0.5 s, out of view for good at 1.2 s.
    (t < 1.2).then(|| {
        head_rest()
            * Isometry3::new(
                Vector3::new(0.05 * (t - 0.5).max(0.0), 0.0, 0.0),
                Vector3::zeros(),
            )
    })
}

#[test]
fn a_hold_decelerates_the_arm_to_standstill_on_its_last_command() {
    let r = run(lost_while_moving, 2.5);
    let ev = r.events();
    let held = ev
        .iter()
        .find(|(_, e)| matches!(e, Event::Hold(Reason::MarkerInvalid)))
        .map(|(t, _)| *t);
    let held = held.unwrap_or_else(|| panic!("{ev:?}"));
    // Moving when the hold began, standing 0.3 s later (40 rad/s² stops 1 rad/s in 0.025 s).
    assert!(largest_step(&r, held - 0.05, held) > 1e-4);
    assert!(
        largest_step(&r, held + 0.3, 2.5) < 1e-9,
        "{}",
        largest_step(&r, held + 0.3, 2.5)
    );
}

#[test]
fn a_goal_set_while_running_is_checked_first_and_a_refused_one_changes_nothing() {
    let arm = Arm::new(Model::Ur3e);
    let cfg = LoopConfig::new(
        base_from_tracker(),
        flange_from_coil(),
        head_from_coil_goal(),
        PERIOD,
    );
    let mut comp = Compensator::new(cfg, arm, PERIOD);
    let inside = Isometry3::from_parts(
        mocomp_geom::nalgebra::Translation3::new(0.0, 0.0, 0.05),
        head_from_coil_goal().rotation,
    );
    assert!(matches!(
        comp.set_goal(&inside),
        Err(mocomp_control::GoalError::InsideHead { .. })
    ));
    assert_eq!(comp.config().head_from_coil_goal, head_from_coil_goal());
    let higher = head_from_coil_goal() * Isometry3::translation(0.0, 0.0, -0.01);
    comp.set_goal(&higher).unwrap();
    assert_eq!(comp.config().head_from_coil_goal, higher);
}

#[test]
fn a_failed_tracker_reader_holds_with_its_cause_named_and_tracking_resumes_after() {
    // From 2 s the tracker's reader fails (its samples stop); at 3 s it is back (reconnected).
    let (run, _) = run_with_tracker(at_rest, 5.0, |t, _, _, poses| {
        poses.silent = (2.0..3.0).contains(&t);
        if t >= 2.0 {
            poses.failures = 1;
        }
    });
    let events = run.events();
    let held: Vec<f64> = events
        .iter()
        .filter(|(_, e)| *e == Event::Hold(Reason::TrackerInputFailed(1)))
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(held.len(), 1, "{events:?}");
    assert!(held[0] > 2.0 && held[0] < 3.0, "{events:?}");
    assert!(
        !events
            .iter()
            .any(|(_, e)| matches!(e, Event::Hold(Reason::TrackerStale(_)))),
        "the hold names the failure, not a stale tracker: {events:?}"
    );
    assert!(
        events.iter().any(|(t, e)| *t > 3.0 && *e == Event::Resume),
        "{events:?}"
    );
    assert_eq!(run.records.last().unwrap().mode, Mode::Tracking);
}
