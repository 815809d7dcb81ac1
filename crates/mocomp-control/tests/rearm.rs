//! A controller that stopped the arm itself is not forgotten (issue 29): the loop in memory,
//! faults set by hand. A fault the controller reports (its program stopped, a protective stop,
//! the connection lost) and a state stream silent for `robot_rearm_after_s` latch: a healthy
//! robot afterwards does not bring the coil back until the operator re-arms, and then it comes
//! back from where the arm is, by a path. A short gap in the state stream, the program still
//! running, resumes by itself.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

mod common;
use common::mem::{PERIOD, World};
use mocomp_control::{Event, Mode, Reason};
use mocomp_robot::{RuntimeState, SafetyMode};
use mocomp_ur::{RobotFault, program};

/// One second of a healthy robot after a fault: the loop stays in `mode`, sending no motion
/// command.
fn stays_faulted(w: &mut World, mode: Mode) {
    let seq = w.robot.seq;
    let modes = w.run(500);
    assert!(
        modes.iter().all(|(m, _)| *m == mode),
        "{:?}",
        modes.iter().find(|(m, _)| *m != mode)
    );
    assert_eq!(w.robot.seq, seq, "no command while latched");
}

/// After the re-arm: the event, then back to tracking by a path within 4 s.
fn comes_back_after_rearm(w: &mut World) {
    assert!(w.comp.rearm(), "a fault was latched");
    assert_eq!(w.comp.latched(), None);
    let modes = w.run(2000);
    assert_eq!(modes[0].1, Some(Event::Rearmed));
    assert!(
        modes.iter().any(|(m, _)| *m == Mode::Approaching),
        "back by a path"
    );
    assert_eq!(modes.last().unwrap().0, Mode::Tracking);
}

#[test]
fn a_program_stopped_by_the_controller_latches_until_the_operator_rearms() {
    let mut w = World::new();
    w.robot.state.runtime_state = RuntimeState::Stopped;
    let modes = w.run(3);
    let stopped = Mode::Faulted(Reason::Robot(RobotFault::ProgramStopped));
    assert_eq!(modes[0].0, stopped);
    assert_eq!(
        modes[0].1,
        Some(Event::Hold(Reason::Robot(RobotFault::ProgramStopped)))
    );
    assert_eq!(
        w.comp.latched(),
        Some(Reason::Robot(RobotFault::ProgramStopped))
    );
    // Someone starts a program again (the pendant, another client): healthy, but the loop does
    // not move the arm on its own.
    w.robot.state.runtime_state = RuntimeState::Playing;
    w.robot.state.program_mode = program::mode::IDLE;
    stays_faulted(&mut w, stopped);
    comes_back_after_rearm(&mut w);
}

#[test]
fn a_protective_stop_latches_and_a_rearm_while_it_lasts_latches_again() {
    let mut w = World::new();
    w.robot.state.safety_mode = SafetyMode::ProtectiveStop;
    let protective = Mode::Faulted(Reason::Robot(RobotFault::ProtectiveStop));
    assert_eq!(w.run(1)[0].0, protective);
    // A re-arm while the stop is still there changes nothing: the rule fires and latches again.
    assert!(w.comp.rearm());
    assert_eq!(w.run(1)[0].0, protective);
    assert!(w.comp.latched().is_some());
    // Unlocked (and the program running again): still the operator's decision.
    w.robot.state.safety_mode = SafetyMode::Normal;
    w.robot.state.program_mode = program::mode::IDLE;
    stays_faulted(&mut w, protective);
    comes_back_after_rearm(&mut w);
}

#[test]
fn a_short_gap_in_the_state_resumes_by_itself_and_a_long_one_waits_for_the_operator() {
    let p = mocomp_control::LoopParams::default();
    let mut w = World::new();
    // 60 ms without a state (past robot_stale_s, the program still running): the loop stops the
    // robot itself, then resumes by itself.
    let now = w.tracker.now;
    w.robot.state.received_s = now - 0.06;
    w.robot.state.controller_s = now - 0.06;
    assert_eq!(w.cycle_at(now).mode, Mode::Faulted(Reason::RobotStale));
    assert_eq!(w.comp.latched(), None);
    w.tracker.now = now + PERIOD;
    w.robot.state.program_mode = program::mode::IDLE;
    let modes = w.run(2000);
    assert_eq!(modes.last().unwrap().0, Mode::Tracking);
    assert!(!modes.iter().any(|(_, e)| *e == Some(Event::Rearmed)));
    // A gap as long as robot_rearm_after_s: latched.
    let now = w.tracker.now;
    let gap = p.robot_rearm_after_s + 0.01;
    w.robot.state.received_s = now - gap;
    w.robot.state.controller_s = now - gap;
    assert_eq!(w.cycle_at(now).mode, Mode::Faulted(Reason::RobotStale));
    assert_eq!(w.comp.latched(), Some(Reason::RobotStale));
    w.tracker.now = now + PERIOD;
    w.robot.state.program_mode = program::mode::IDLE;
    stays_faulted(&mut w, Mode::Faulted(Reason::RobotStale));
    comes_back_after_rearm(&mut w);
}

#[test]
fn a_rearm_without_a_latched_fault_does_nothing() {
    let mut w = World::new();
    assert!(!w.comp.rearm());
    let modes = w.run(10);
    assert!(
        modes
            .iter()
            .all(|(m, e)| *m == Mode::Tracking && e.is_none())
    );
}
