//! The phases' shared fixture, and the tests of the mode machine and the target phase. Each
//! phase's own tests sit in its file; the whole loop's in `tests/`.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use super::sense::HeadEstimate;
use super::*;
use crate::safety::backed_off;
use crate::supervisor::Reaction;
use mocomp_kin::{Model, Selection};
use mocomp_testkit::mem::MemRobot;
use mocomp_testkit::scene::{base_from_tracker, flange_from_coil, head_from_coil_goal, head_rest};

const PERIOD: f64 = 0.002;

/// A loop for a UR3e with the scene's goal, and an in-memory robot with the coil on its goal.
pub(super) fn fixture() -> (Compensator, MemRobot) {
    let arm = Arm::new(Model::Ur3e);
    let cfg = LoopConfig::new(
        base_from_tracker(),
        flange_from_coil(),
        head_from_coil_goal(),
        PERIOD,
    );
    let c = Compensator::new(cfg, arm, PERIOD);
    let q = at_goal(&c, 0.0);
    let robot = MemRobot::at(q, arm.fk(&q), PERIOD);
    (c, robot)
}

/// The joints with the coil `standoff` m back along its axis from the goal (negative: in), the
/// head at rest, on the branch of a usual overhead pose.
pub(super) fn at_goal(c: &Compensator, standoff: f64) -> [f64; 6] {
    let flange =
        head_rest() * backed_off(&c.cfg.head_from_coil_goal, standoff) * c.coil_from_flange;
    c.arm
        .ik_closest(
            &flange,
            &[0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
            &Selection::tracking(0.05),
        )
        .unwrap()
        .joints
}

#[test]
fn a_mode_change_reports_once_per_kind_and_says_how_it_came_back() {
    use Mode::*;
    let (a, b) = (Reason::TrackerStale(0.2), Reason::TrackerStale(0.3));
    assert_eq!(transition_event(Holding(a), Holding(a)), None);
    // A reason whose value moves is the same hold.
    assert_eq!(transition_event(Holding(a), Holding(b)), None);
    assert_eq!(
        transition_event(Holding(a), Holding(Reason::Operator)),
        Some(Event::Hold(Reason::Operator))
    );
    assert_eq!(
        transition_event(Holding(a), Faulted(Reason::RobotStale)),
        Some(Event::Hold(Reason::RobotStale))
    );
    let coil = Reason::CoilCollision(0.001);
    assert_eq!(
        transition_event(Tracking, Retreating(coil)),
        Some(Event::Retreat(coil))
    );
    // A retreat for another reason of the same kind is the same retreat; a hold is news.
    assert_eq!(
        transition_event(Retreating(coil), Retreating(Reason::CoilCollision(0.002))),
        None
    );
    assert_eq!(
        transition_event(Retreating(coil), Holding(coil)),
        Some(Event::Hold(coil))
    );
    assert_eq!(
        transition_event(Approaching, Tracking),
        Some(Event::Reached)
    );
    assert_eq!(transition_event(Holding(a), Tracking), Some(Event::Resume));
    assert_eq!(
        transition_event(Holding(a), Approaching),
        Some(Event::Resume)
    );
    // Only the door changes the mode.
    let (mut c, _) = fixture();
    assert_eq!(c.transition(Tracking), Some(Event::Resume));
    assert_eq!(c.mode(), Tracking);
}

fn track(c: &mut Compensator, now: f64) -> ([f64; 6], Option<Event>) {
    let head = HeadEstimate {
        base_from_head: Some(head_rest()),
        required: c.cfg.params.coil_min_distance_m,
        base_from_head_before: None,
    };
    let goal_q = c
        .goal_joints(Reaction::Track, head.base_from_head.as_ref())
        .unwrap();
    let decision = decide(&RuleInputs::default());
    let mut rec = CycleRecord::new(now, c.mode, c.cmd.q);
    let mut event = None;
    let (q, _) = c.target(now, decision, goal_q, &head, &mut rec, &mut event);
    (q, event)
}

#[test]
fn a_hold_waits_out_the_resume_time_then_comes_straight_back_on_its_goal() {
    let (mut c, _) = fixture();
    c.cmd.q = at_goal(&c, 0.0);
    let resume = c.cfg.params.resume_after_s;
    // Held until the reason has been clear for the resume time, standing on its command.
    let (q, event) = track(&mut c, 1.0);
    assert_eq!((q, event), (c.cmd.q, None));
    assert!(matches!(c.mode(), Mode::Holding(_)));
    let (_, event) = track(&mut c, 1.0 + resume * 0.99);
    assert_eq!(event, None);
    // Then on the goal: straight to tracking, no path.
    let (q, event) = track(&mut c, 1.0 + resume * 1.01);
    assert_eq!((c.mode(), event), (Mode::Tracking, Some(Event::Resume)));
    assert!(c.approach.path.is_none());
    let goal = at_goal(&c, 0.0);
    assert!((0..6).all(|j| (q[j] - goal[j]).abs() < 1e-9));
}

#[test]
fn off_its_goal_the_coil_comes_back_by_a_path_never_straight() {
    let (mut c, _) = fixture();
    c.cmd.q = at_goal(&c, 0.04);
    let resume = c.cfg.params.resume_after_s;
    track(&mut c, 1.0);
    let (q, event) = track(&mut c, 1.0 + resume * 1.01);
    assert_eq!((c.mode(), event), (Mode::Approaching, Some(Event::Resume)));
    assert!(matches!(c.approach.path, Some(Plan::Shell(_))));
    // The first step is along the path, a tiny move from the command, not the goal's joints.
    let step = (0..6).fold(0.0f64, |m, j| m.max((q[j] - c.cmd.q[j]).abs()));
    assert!(step < 1e-3, "{step}");
}

/// A loop holding for the operator with its coil on the goal, the coil's clearance there, the
/// decision and a record to target with.
fn held_on_goal() -> (Compensator, f64, Decision, CycleRecord) {
    let (mut c, _) = fixture();
    c.cmd.q = at_goal(&c, 0.0);
    let clearance = c.coil_distance(&c.head_from_coil_at(&c.cmd.q, &head_rest()));
    let rec = CycleRecord::new(1.0, c.mode, c.cmd.q);
    (c, clearance, Decision::hold(Reason::Operator), rec)
}

#[test]
fn a_hold_with_a_head_that_comes_in_gives_way_and_without_one_stands() {
    let (mut c, clearance, decision, mut rec) = held_on_goal();
    let mut event = None;
    // The filter requires more than the coil has: it backs off along its axis.
    let near = HeadEstimate {
        base_from_head: Some(head_rest()),
        required: clearance + 0.002,
        base_from_head_before: None,
    };
    let (q, _) = c.target(1.0, decision, None, &near, &mut rec, &mut event);
    assert!(matches!(
        c.mode(),
        Mode::Retreating(Reason::CoilCollision(_))
    ));
    assert!(matches!(event, Some(Event::Retreat(_))));
    let out = c.coil_distance(&c.head_from_coil_at(&q, &head_rest()));
    assert!(out > clearance + 0.01, "{out} vs {clearance}");
    // Without a head in view: a plain hold, standing.
    let (mut c, _) = fixture();
    c.cmd.q = at_goal(&c, 0.0);
    let unknown = HeadEstimate {
        base_from_head: None,
        required: 0.0,
        base_from_head_before: None,
    };
    let mut event = None;
    let (q, _) = c.target(1.0, decision, None, &unknown, &mut rec, &mut event);
    assert_eq!((q, c.mode()), (c.cmd.q, Mode::Holding(Reason::Operator)));
}

#[test]
fn a_coil_that_gave_way_holds_once_the_head_keeps_within_the_filters_noise() {
    let (mut c, clearance, decision, mut rec) = held_on_goal();
    let mut event = None;
    let at = |required: f64| HeadEstimate {
        base_from_head: Some(head_rest()),
        required,
        base_from_head_before: None,
    };
    // The head comes in: the coil gives way.
    c.target(
        1.0,
        decision,
        None,
        &at(clearance + 0.002),
        &mut rec,
        &mut event,
    );
    assert!(matches!(c.mode(), Mode::Retreating(_)));
    let wait = c.cfg.params.retreat_resume_s;
    // Where the coil rests the requirement moves a tenth of a millimetre either way each
    // cycle (the prediction's uncertainty): that starts no new wait, and it holds again.
    let mut t = 1.0;
    while t < 1.0 + 2.0 * wait {
        t += PERIOD;
        let jitter = if (t / PERIOD) as i64 % 2 == 0 {
            1e-4
        } else {
            -1e-4
        };
        let rest = c.coil_distance(&c.head_from_coil_at(&c.cmd.q, &head_rest()));
        let (q, _) = c.target(t, decision, None, &at(rest + jitter), &mut rec, &mut event);
        c.cmd.q = q;
    }
    assert_eq!(c.mode(), Mode::Holding(Reason::Operator));
    // A head that comes closer by more than that: it gives way again.
    let rest = c.coil_distance(&c.head_from_coil_at(&c.cmd.q, &head_rest()));
    c.target(
        t + PERIOD,
        decision,
        None,
        &at(rest + 0.001),
        &mut rec,
        &mut event,
    );
    assert!(matches!(c.mode(), Mode::Retreating(_)));
}

#[test]
fn a_retreat_backs_the_goal_off_at_once_and_returns_softly() {
    let (mut c, _) = fixture();
    let bh = head_rest();
    let mut rec = CycleRecord::new(0.0, c.mode, c.cmd.q);
    let p = c.cfg.params;
    c.update_standoff(&bh, p.coil_min_distance_m, Reaction::Retreat, &mut rec);
    assert_eq!(c.standoff.distance, p.retreat_distance_m);
    assert_eq!(rec.standoff_m, p.retreat_distance_m);
    // Clear again: it shrinks by at most standoff_return_m_s per second.
    let mut last = c.standoff.distance;
    for _ in 0..5000 {
        c.update_standoff(&bh, p.coil_min_distance_m, Reaction::Track, &mut rec);
        let shrink = last - c.standoff.distance;
        assert!(shrink >= 0.0 && shrink <= p.standoff_return_m_s * c.cmd.dt + 1e-12);
        last = c.standoff.distance;
    }
    assert!(c.standoff.distance < 1e-4, "{}", c.standoff.distance);
}

#[test]
fn a_goal_out_of_reach_is_its_own_hold() {
    let (mut c, _) = fixture();
    c.cmd.q = at_goal(&c, 0.0);
    // The head 2 m away: no IK solution.
    let far = Isometry3::translation(2.0, 0.0, 0.0) * head_rest();
    assert_eq!(
        c.goal_joints(Reaction::Track, Some(&far)),
        Err(Reason::Unreachable)
    );
    // Holding, no goal joints are solved.
    assert_eq!(c.goal_joints(Reaction::Hold, Some(&far)), Ok(None));
    let near = head_rest();
    assert!(matches!(
        c.goal_joints(Reaction::Track, Some(&near)),
        Ok(Some(_))
    ));
}

/// The head sliding 50 mm/s along the base's x and turning 0.3 rad/s about its z from rest,
/// its whole path moved `shift` m along y (a new sample's correction).
fn sliding_head(t: f64, shift: f64) -> Isometry3<f64> {
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion, Vector3};
    let rest = head_rest();
    let turned = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3 * t) * rest.rotation;
    Isometry3::from_parts(
        Translation3::from(rest.translation.vector + Vector3::new(0.05 * t, shift, 0.0)),
        turned,
    )
}

/// The goal's joints for the head at `base_from_head`.
fn goal_at(c: &Compensator, base_from_head: &Isometry3<f64>) -> [f64; 6] {
    c.goal_joints(Reaction::Track, Some(base_from_head))
        .unwrap()
        .unwrap()
        .0
}

#[test]
fn the_targets_speed_is_along_the_prediction_and_a_moved_path_is_no_speed() {
    let (mut c, _) = fixture();
    c.cmd.q = at_goal(&c, 0.0);
    c.mode = Mode::Tracking;
    let t = 0.1;
    let estimate = |shift: f64| HeadEstimate {
        base_from_head: Some(sliding_head(t, shift)),
        required: 0.0,
        base_from_head_before: Some(sliding_head(t - PERIOD, shift)),
    };
    let speed_of = |c: &Compensator, shift: f64| {
        let q = goal_at(c, &sliding_head(t, shift));
        c.target_speed(Some((q, 1.0)), &q, &estimate(shift))
            .unwrap()
    };
    // The goal's own joint speed, centred over a millisecond.
    let h = 5e-4;
    let (ahead, behind) = (
        goal_at(&c, &sliding_head(t + h, 0.0)),
        goal_at(&c, &sliding_head(t - h, 0.0)),
    );
    let truth: [f64; 6] = std::array::from_fn(|j| (ahead[j] - behind[j]) / (2.0 * h));
    let norm = |v: &[f64; 6]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let speed = speed_of(&c, 0.0);
    let off: [f64; 6] = std::array::from_fn(|j| speed[j] - truth[j]);
    assert!(norm(&truth) > 0.1, "{truth:?}");
    assert!(
        norm(&off) < 0.01 * norm(&truth),
        "{speed:?} against {truth:?}"
    );
    // A sample that moves the whole path by 2 mm leaves the speed as it was; the target's
    // last two values would say the joints flew.
    let moved = speed_of(&c, 0.002);
    let change: [f64; 6] = std::array::from_fn(|j| moved[j] - speed[j]);
    assert!(
        norm(&change) < 0.01 * norm(&truth),
        "{moved:?} against {speed:?}"
    );
    let (last, now) = (
        goal_at(&c, &sliding_head(t - PERIOD, 0.0)),
        goal_at(&c, &sliding_head(t, 0.002)),
    );
    let jumped: [f64; 6] = std::array::from_fn(|j| (now[j] - last[j]) / PERIOD - speed[j]);
    assert!(norm(&jumped) > 5.0 * norm(&truth), "{jumped:?}");
    // Only the goal itself has it: not a command elsewhere, not a hold.
    let q = goal_at(&c, &sliding_head(t, 0.0));
    let elsewhere = c.cmd.q;
    assert_eq!(
        c.target_speed(Some((q, 1.0)), &elsewhere, &estimate(0.0)),
        None
    );
    c.mode = Mode::Holding(Reason::Operator);
    assert_eq!(c.target_speed(Some((q, 1.0)), &q, &estimate(0.0)), None);
}

/// The command `standoff` m back from the goal, and the setpoint the loop sends for it while
/// the command catches up towards the head at 0.5 rad/s (its largest joint) from standing.
fn lead_into_the_head(standoff: f64) -> (Compensator, [f64; 6], [f64; 6], Isometry3<f64>) {
    let (mut c, mut robot) = fixture();
    let bh = head_rest();
    // Where the coil touches the scalp, along its axis from the goal.
    let touch = -c.commanded_clearance(&at_goal(&c, 0.0), &bh, clearance::Site::Recorded);
    let q = at_goal(&c, touch + standoff);
    let inwards: [f64; 6] = {
        let deeper = at_goal(&c, touch + standoff - 0.01);
        std::array::from_fn(|j| deeper[j] - q[j])
    };
    let top = inwards.iter().fold(0.0_f64, |m, d| m.max(d.abs()));
    c.mode = Mode::Tracking;
    c.cmd.have = true;
    c.cmd.dt = PERIOD;
    c.cmd.v = std::array::from_fn(|j| 0.5 * inwards[j] / top);
    c.cmd.target_speed = Some([0.0; 6]);
    c.cmd.catch_up = Some([0.0; 6]);
    let mut rec = CycleRecord::new(0.0, c.mode, q);
    rec.required_m = 0.0;
    c.command(0.0, &mut robot, q, Some(&bh), &mut rec);
    (c, q, rec.q_setpoint, bh)
}

#[test]
fn the_setpoints_lead_never_takes_it_into_the_head() {
    // Well clear of the head, the catch-up's lead takes the setpoint nearer it than the command.
    let (c, q, set, bh) = lead_into_the_head(0.02);
    assert_ne!(set, q);
    let site = clearance::Site::Recorded;
    let (at_q, at_set) = (
        c.commanded_clearance(&q, &bh, site),
        c.commanded_clearance(&set, &bh, site),
    );
    assert!(at_set < at_q - 1e-4, "{at_set} vs {at_q}");
    // Just off the scalp, the same lead would enter it: none.
    let (c, q, set, bh) = lead_into_the_head(0.0002);
    assert!(c.commanded_clearance(&q, &bh, clearance::Site::Recorded) > 0.0);
    assert_eq!(set, q);
    assert!(c.cmd.lead.iter().all(|l| *l == 0.0), "{:?}", c.cmd.lead);
}
