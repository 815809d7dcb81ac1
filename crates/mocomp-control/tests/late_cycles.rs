//! A late cycle is not a fault (issue 15): the loop on a busy PC, in memory, with the state's
//! times set by hand. A state a few periods late does not hold the loop; after any gap the next
//! command stays within one controller period's setpoint limit (issue 29) and the loop makes up
//! the time after; a cycle on the same state moves nothing; after a stop the loop continues the
//! arm's motion.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::mem::{PERIOD, World};
use mocomp_control::{Mode, Reason};
use mocomp_kin::{Arm, Model};
use mocomp_robot::SafetyMode;
use mocomp_ur::RobotFault;

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
fn after_any_gap_the_next_command_stays_within_one_controller_periods_setpoint_limit() {
    // The controller judges each setpoint against the one before, which it may have taken only
    // one period ago however late the state is (a controller that stalled and caught up, a
    // network that held the previous command back): every command is checked over one period.
    let mut w = World::new();
    // Into the fast part of the nod (the command moves every cycle).
    for _ in 0..300 {
        w.cycle();
    }
    let mut late_steps = 0;
    for k in 0..2000 {
        let before = w.robot.state.actual_q;
        let t_before = w.robot.state.controller_s;
        // Every seventh cycle comes 3 to 14 periods late (up to 28 ms, inside robot_stale_s);
        // the rest on time.
        let gap = if k % 7 == 3 {
            (3 + k % 12) as f64 * PERIOD
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
            within_setpoint_limit(&before, &after, PERIOD),
            "cycle {k}: a setpoint jump after a {gap} s gap: {before:?} → {after:?}"
        );
        if gap > PERIOD {
            late_steps += usize::from(max_step(&before, &after) > 1e-6);
        }
    }
    assert!(late_steps > 200, "late cycles moved the arm: {late_steps}");
}

#[test]
fn a_late_cycle_steps_no_further_than_one_on_time_and_the_loop_makes_up_the_time_after() {
    // Two identical worlds; one cycle on time in the first, the same cycle 15 periods late (30
    // ms, the gap that made the controller stop in issue 29) in the second.
    // The loop's commands are compared: the setpoint sent leads a command's catch-up by the
    // servo's lag behind it, bounded on its own (the setpoint's step by the command's speed
    // ceiling, or the command's own step; unit-tested in `compensator::command`).
    let (mut a, mut b) = (World::new(), World::new());
    let on_time = |w: &mut World| {
        let now = w.tracker.now;
        w.robot.state.received_s = now;
        w.robot.state.controller_s = now;
        let r = w.cycle_at(now);
        w.tracker.now += PERIOD;
        r.q_command
    };
    let (mut before, mut q0) = ([0.0; 6], [0.0; 6]);
    for _ in 0..400 {
        before = q0;
        q0 = on_time(&mut a);
        assert_eq!(q0, on_time(&mut b), "deterministic");
    }
    let t0 = a.robot.state.controller_s;
    let gap = 14.0 * PERIOD;
    let mut stepped = [[0.0; 6]; 2];
    for (i, (w, gap)) in [(&mut a, PERIOD), (&mut b, gap)].into_iter().enumerate() {
        w.robot.state.controller_s = t0 + gap;
        w.robot.state.received_s = t0 + gap;
        stepped[i] = w.cycle_at(t0 + gap).q_command;
    }
    let (sa, sb) = (max_step(&q0, &stepped[0]), max_step(&q0, &stepped[1]));
    assert!(sa > 1e-5, "the arm moves: {sa}");
    // Either step is one an on-time cycle could take: the last step's speed changed by at most
    // the acceleration of one period (each joint; the two may use that window differently).
    let accel = a.comp.config().params.max_joint_accel_rad_s2 * PERIOD * PERIOD;
    let last = max_step(&before, &q0);
    for s in [sa, sb] {
        assert!(
            s <= last + accel + 1e-12,
            "last step {last}, on time {sa}, late {sb}"
        );
    }
    // The late world is behind by the gap; within half a second it is where a third world that
    // was on time throughout is at the same time.
    let mut c = World::new();
    for _ in 0..400 {
        c.cycle();
    }
    let step_on = |w: &mut World| {
        let now = w.robot.state.controller_s + PERIOD;
        w.robot.state.controller_s = now;
        w.robot.state.received_s = now;
        let r = w.cycle_at(now);
        assert_eq!(r.mode, Mode::Tracking);
    };
    for _ in 0..14 {
        step_on(&mut c);
    }
    assert!((c.robot.state.controller_s - b.robot.state.controller_s).abs() < 1e-9);
    let behind = max_step(&b.robot.state.actual_q, &c.robot.state.actual_q);
    for _ in 0..250 {
        step_on(&mut b);
        step_on(&mut c);
    }
    let after = max_step(&b.robot.state.actual_q, &c.robot.state.actual_q);
    assert!(behind > 1e-3, "the late world fell behind: {behind} rad");
    assert!(after < 1e-5, "and caught up: {behind} rad → {after} rad");
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
    assert_eq!(r.q_setpoint, q, "no controller time passed, no step");
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
    // … then healthy again, the operator re-armed, with the arm still moving (as it does
    // while it brakes).
    w.robot.state.safety_mode = SafetyMode::Normal;
    assert!(w.comp.rearm());
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

#[test]
fn after_a_stale_state_the_loop_commands_again_only_once_the_controller_has_taken_its_stop() {
    // Commands go into the controller's registers: a servo sent before the controller read the
    // stop overwrites it, and the controller judges it against the setpoint it still servoes to.
    // Found against a controller in another process (issue 29): after a 40 ms stall, a C204A3.
    let mut w = World::new();
    for _ in 0..300 {
        w.cycle();
    }
    let now = w.tracker.now;
    w.robot.state.received_s = now - 0.05;
    w.robot.state.controller_s = now - 0.05;
    let r = w.cycle_at(now);
    assert_eq!(r.mode, Mode::Faulted(Reason::RobotStale));
    assert_eq!(w.robot.stops, 1);
    let stop_seq = w.robot.state.acked_seq;
    // The controller is back, still servoing: it has not read the stop yet.
    w.robot.state.acked_seq = stop_seq - 1;
    w.robot.state.program_mode = mocomp_ur::program::mode::SERVO;
    let servos = w.robot.seq;
    let alive = w.robot.keep_alives;
    for k in 1..=5 {
        let t = now + k as f64 * PERIOD;
        w.robot.state.controller_s = t;
        w.robot.state.received_s = t;
        let r = w.cycle_at(t);
        assert_eq!(r.mode, Mode::Faulted(Reason::RobotStale), "cycle {k}");
    }
    assert_eq!(w.robot.seq, servos, "no command before the stop is taken");
    assert!(w.robot.keep_alives >= alive + 5, "the link kept alive");
    assert_eq!(w.robot.stops, 1, "the stop is sent once, then kept alive");
    // It takes the stop and brakes (a blocking stopj ignores commands until the arm is still):
    // still no command.
    w.robot.state.acked_seq = stop_seq;
    w.robot.state.program_mode = mocomp_ur::program::mode::STOPPING;
    for k in 6..=10 {
        let t = now + k as f64 * PERIOD;
        w.robot.state.controller_s = t;
        w.robot.state.received_s = t;
        let r = w.cycle_at(t);
        assert_eq!(r.mode, Mode::Faulted(Reason::RobotStale), "cycle {k}");
    }
    assert_eq!(w.robot.seq, servos, "no command while the stop brakes");
    // Still: the loop commands again, from where the arm is.
    w.robot.state.program_mode = mocomp_ur::program::mode::IDLE;
    let q = w.robot.state.actual_q;
    let t = now + 11.0 * PERIOD;
    w.robot.state.controller_s = t;
    w.robot.state.received_s = t;
    let r = w.cycle_at(t);
    assert!(w.robot.seq > servos, "commands again");
    assert!(
        within_setpoint_limit(&q, &r.q_command, PERIOD),
        "{q:?} → {:?}",
        r.q_command
    );
}

#[test]
fn a_controller_still_servoing_its_old_setpoint_gets_the_next_one_from_there_not_from_the_arm() {
    // A stop that never reached the controller (the link was down): it still servoes to the
    // last setpoint, and judges the next against it, wherever the arm is.
    let mut w = World::new();
    for _ in 0..300 {
        w.cycle();
    }
    let last = w.robot.state.actual_q;
    let now = w.tracker.now;
    w.robot.state.received_s = now - 0.05;
    w.robot.state.controller_s = now - 0.05;
    assert_eq!(w.cycle_at(now).mode, Mode::Faulted(Reason::RobotStale));
    // Back, the stop acknowledged by sequence but the program still servoing, the arm lagging
    // its setpoint by 20 mrad on every joint.
    w.robot.state.program_mode = mocomp_ur::program::mode::SERVO;
    w.robot.state.actual_q = last.map(|q| q - 0.02);
    let t = now + PERIOD;
    w.robot.state.controller_s = t;
    w.robot.state.received_s = t;
    let r = w.cycle_at(t);
    assert!(
        within_setpoint_limit(&last, &r.q_command, PERIOD),
        "from the old setpoint {last:?}: {:?}",
        r.q_command
    );
}
