//! A late cycle is not a fault (issue 15): the loop on a busy PC, in memory, with the state's
//! times set by hand. A state a few periods late does not hold the loop; a late cycle steps by
//! the controller time that really passed and never faster than the controller accepts; a cycle
//! on the same state moves nothing; after a stop the loop continues the arm's motion.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::mem::{PERIOD, World};
use mocomp_control::{Mode, Reason};
use mocomp_kin::{Arm, Model};
use mocomp_ur::RobotFault;
use mocomp_ur::robot::SafetyMode;

/// URControl's C204A3 check as the simulator models it: a setpoint change over `dt` implying more
/// than 1.2 × the joint's maximum speed.
fn within_setpoint_limit(a: &[f64; 6], b: &[f64; 6], dt: f64) -> bool {
    let spec = Arm::new(Model::Ur3e).spec();
    (0..6).all(|j| (b[j] - a[j]).abs() / dt.max(PERIOD) <= 1.2 * spec.max_speed[j])
}

fn max_step(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    (0..6).fold(0.0, |m, j| m.max((b[j] - a[j]).abs()))
}

#[test]
fn a_state_a_few_periods_late_does_not_hold_the_loop_a_stale_one_does() {
    let mut w = World::new();
    // 10 ms late (five e-Series periods: the old limit): the loop goes on.
    let now = w.tracker.now;
    w.robot.state.controller_s = now - 0.010;
    w.robot.state.received_s = now - 0.010;
    let r = w.cycle_at(now);
    assert_eq!(r.mode, Mode::Tracking, "{:?}", r.mode);
    // 25 ms: still within robot_stale_s.
    let r = w.cycle_at(now + 0.015);
    assert_eq!(r.mode, Mode::Tracking, "{:?}", r.mode);
    // 40 ms: really stale, the robot is stopped and the reason named.
    let r = w.cycle_at(now + 0.030);
    assert_eq!(r.mode, Mode::Faulted(Reason::RobotStale));
}

#[test]
fn a_late_cycle_steps_by_the_time_that_passed_and_no_faster_than_the_controller_accepts() {
    let mut w = World::new();
    // Into the fast part of the nod (the command moves every cycle).
    for _ in 0..300 {
        w.cycle();
    }
    let mut late_steps = 0;
    for k in 0..2000 {
        let before = w.robot.state.actual_q;
        let t_before = w.robot.state.controller_s;
        // Every seventh cycle comes 3 to 12 periods late; the rest on time.
        let gap = if k % 7 == 3 {
            (3 + k % 10) as f64 * PERIOD
        } else {
            PERIOD
        };
        let now = t_before + gap;
        w.robot.state.controller_s = now;
        w.robot.state.received_s = now;
        let r = w.cycle_at(now);
        assert!(
            matches!(r.mode, Mode::Tracking),
            "cycle {k} (gap {gap}): {:?}",
            r.mode
        );
        let after = w.robot.state.actual_q;
        assert!(
            within_setpoint_limit(&before, &after, gap),
            "cycle {k}: a setpoint jump over {gap} s: {before:?} → {after:?}"
        );
        if gap > PERIOD {
            late_steps += usize::from(max_step(&before, &after) > 1e-6);
        }
    }
    assert!(late_steps > 200, "late cycles moved the arm: {late_steps}");
}

#[test]
fn a_late_cycle_moves_further_than_one_on_time_as_far_as_the_time_allows() {
    // Two identical worlds; one cycle on time in the first, the same cycle three periods late in
    // the second: the late one covers about three times the ground, on the same path.
    let (mut a, mut b) = (World::new(), World::new());
    for _ in 0..400 {
        a.cycle();
        b.cycle();
    }
    assert_eq!(
        a.robot.state.actual_q, b.robot.state.actual_q,
        "deterministic"
    );
    let q0 = a.robot.state.actual_q;
    let t0 = a.robot.state.controller_s;
    for (w, gap) in [(&mut a, PERIOD), (&mut b, 3.0 * PERIOD)] {
        w.robot.state.controller_s = t0 + gap;
        w.robot.state.received_s = t0 + gap;
        w.cycle_at(t0 + gap);
    }
    let (sa, sb) = (
        max_step(&q0, &a.robot.state.actual_q),
        max_step(&q0, &b.robot.state.actual_q),
    );
    assert!(sa > 1e-5, "the arm moves: {sa}");
    assert!(
        sb > 2.0 * sa && sb < 4.0 * sa,
        "on time {sa}, 3 periods late {sb}"
    );
}

#[test]
fn a_cycle_on_the_same_state_moves_nothing() {
    let mut w = World::new();
    for _ in 0..300 {
        w.cycle();
    }
    let q = w.robot.state.actual_q;
    let t = w.robot.state.controller_s;
    // Woken without a new state (the loop's patience ran out): same controller time.
    let r = w.cycle_at(t + 3.0 * PERIOD);
    assert_eq!(r.mode, Mode::Tracking);
    assert_eq!(r.q_command, q, "no controller time passed, no step");
}

#[test]
fn after_a_stop_the_loop_continues_the_arms_motion_instead_of_jerking_it() {
    let mut w = World::new();
    for _ in 0..300 {
        w.cycle();
    }
    // A protective stop for a moment…
    w.robot.state.safety_mode = SafetyMode::ProtectiveStop;
    let now = w.tracker.now;
    w.robot.state.controller_s = now;
    w.robot.state.received_s = now;
    let r = w.cycle_at(now);
    assert_eq!(
        r.mode,
        Mode::Faulted(Reason::Robot(RobotFault::ProtectiveStop))
    );
    // … then healthy again, with the arm still moving (as it does while it brakes).
    w.robot.state.safety_mode = SafetyMode::Normal;
    let qd = [0.2, -0.1, 0.15, 0.0, 0.05, -0.3];
    w.robot.state.actual_qd = qd;
    let q = w.robot.state.actual_q;
    let t = now + PERIOD;
    w.robot.state.controller_s = t;
    w.robot.state.received_s = t;
    let r = w.cycle_at(t);
    // The first command carries the arm on by about its speed × one period (the limiter then
    // brakes it within its acceleration), not back to where it is.
    let accel = w.comp.config().params.max_joint_accel_rad_s2 * PERIOD * PERIOD;
    for j in 0..6 {
        let step = r.q_command[j] - q[j];
        assert!(
            (step - qd[j] * PERIOD).abs() <= accel + 1e-12,
            "joint {j}: step {step} for speed {}",
            qd[j]
        );
    }
}
