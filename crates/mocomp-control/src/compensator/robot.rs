//! The robot's rules, first in the cycle after the tracker's samples: a fault (latched until
//! the operator re-arms, [`crate::supervisor::latches`]) stops the arm and ends the cycle; so
//! does a stop the controller has not yet taken, and free-drive, where the hand moves the arm.
//! Otherwise the cycle goes on with the robot's state.

use super::{Compensator, CycleRecord, Mode};
use crate::supervisor::{Reason, latches, robot_rules};
use mocomp_robot::{Robot, RobotState};

/// The robot's side of a fault: what latched and the stop sent for it.
#[derive(Debug, Clone, Default)]
pub(super) struct FaultState {
    /// A robot fault that stays until the operator re-arms ([`crate::supervisor::latches`]).
    pub(super) latched: Option<Reason>,
    /// The operator re-armed since the last cycle: its event is the next cycle's.
    pub(super) rearmed: bool,
    /// A stop has been sent for the fault in force.
    pub(super) stop_sent: bool,
    /// The sequence number of the stop sent for a fault, until the controller has taken it.
    pub(super) stop_seq: Option<i32>,
}

/// How the robot phase ends.
// Not boxed: the cycle allocates nothing, and the state is used at once.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, Copy)]
pub(super) enum RobotStep {
    /// The robot is healthy and commandable: the cycle goes on with its state.
    Ready(RobotState),
    /// The cycle ends here, in this mode (`None`: the mode stays).
    Done(Option<Mode>),
}

impl Compensator {
    /// The robot rules on the robot's newest state at loop time `now`.
    pub(super) fn robot_phase<R: Robot + ?Sized>(
        &mut self,
        now: f64,
        robot: &mut R,
        rec: &mut CycleRecord,
    ) -> RobotStep {
        let state = robot.state();
        if let Some(s) = state {
            rec.q_actual = s.actual_q;
            rec.qd_actual = s.actual_qd;
            rec.robot_s = s.controller_s;
            self.cmd.delay.measure(s.acked_seq, s.received_s);
            self.cmd.held.acknowledge(s.acked_seq, s.controller_s);
        }
        let fired = robot_rules(state.as_ref(), now, &self.cfg.params);
        if let Some(r) = fired
            && self.fault.latched.is_none()
        {
            let stale_for = state.map_or(f64::INFINITY, |s| now - s.received_s);
            if latches(&r, stale_for, &self.cfg.params) {
                self.fault.latched = Some(r);
            }
        }
        // A rule that fires now names the fault; a cleared one that latched keeps it.
        if let Some(r) = fired.or(self.fault.latched) {
            // Reaction::Fault, the only reaction of the robot rules.
            if self.fault.stop_sent {
                // The stop again (an edge command: it runs once), so the controller's watchdog
                // sees the client alive and the stop is there to take when it reads again.
                let _ = robot.keep_alive();
            } else {
                // Best effort: the robot may be unreachable.
                self.fault.stop_seq = robot.stop(self.cfg.params.stop_decel_rad_s2).ok();
                self.fault.stop_sent = true;
            }
            self.cmd.have = false;
            self.clear_since = None;
            return RobotStep::Done(Some(Mode::Faulted(r)));
        }
        let Some(state) = state else {
            return RobotStep::Done(None);
        };
        if let Some(seq) = self.fault.stop_seq
            && !self.cmd.have
        {
            if state.acked_seq.wrapping_sub(seq) < 0
                || state.program_mode == mocomp_robot::mode::STOPPING
            {
                // Healthy again, but the controller has not yet taken the stop, or is still in it:
                // commands go into registers, so a command sent before it read the stop would
                // overwrite it and be judged against the old setpoint it still servoes to (a
                // jump); and a blocking stopj ignores commands until the arm is still, then judges
                // the next against where the arm stopped. Wait for the stop to finish, keeping
                // the link alive.
                let _ = robot.keep_alive();
                return RobotStep::Done(None);
            }
            self.fault.stop_seq = None;
        }
        self.fault.stop_sent = false;
        if self.operator.freedrive {
            self.freedrive_step(now, robot, &state, rec);
            return RobotStep::Done(Some(Mode::Holding(Reason::HandGuided)));
        }
        RobotStep::Ready(state)
    }

    /// The hand moves the arm: the loop keeps free-drive alive, follows where the arm is and
    /// keeps estimating the head (to teach the coil's pose on it).
    fn freedrive_step<R: Robot + ?Sized>(
        &mut self,
        now: f64,
        robot: &mut R,
        state: &RobotState,
        rec: &mut CycleRecord,
    ) {
        self.cmd.have = false;
        self.cmd.last_controller_s = state.controller_s;
        self.cmd.q = state.actual_q;
        rec.q_command = state.actual_q;
        if let Ok(seq) = robot.freedrive() {
            self.cmd.delay.note(seq, now);
        }
        rec.head_speed = self.head.speed();
        if self.head.predictor.is_initialised() {
            rec.sample_age_s = now - self.head.predictor.time_s();
        }
        if let Some(tracker_from_head) = self.head.predictor.predict(now) {
            rec.head_now = Some(tracker_from_head);
            let m = self.measured(&state.actual_q, &tracker_from_head);
            (rec.deviation, rec.coil_error, rec.coil_now) =
                (m.deviation, m.coil_error, Some(m.head_from_coil));
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::super::tests::fixture;
    use super::*;
    use mocomp_robot::SafetyMode;

    #[test]
    fn a_protective_stop_stops_once_latches_and_ends_the_cycle() {
        let (mut c, mut robot) = fixture();
        robot.tick(1.0);
        robot.state.safety_mode = SafetyMode::ProtectiveStop;
        let mut rec = CycleRecord::new(1.0, c.mode, c.cmd.q);
        let step = c.robot_phase(1.0, &mut robot, &mut rec);
        assert!(matches!(
            step,
            RobotStep::Done(Some(Mode::Faulted(Reason::Robot(_))))
        ));
        assert_eq!(robot.stops, 1);
        assert!(matches!(c.fault.latched, Some(Reason::Robot(_))));
        // Healthy again: still faulted (latched), the stop not sent again but kept alive.
        robot.state.safety_mode = SafetyMode::Normal;
        robot.tick(1.002);
        let step = c.robot_phase(1.002, &mut robot, &mut rec);
        assert!(matches!(step, RobotStep::Done(Some(Mode::Faulted(_)))));
        assert_eq!((robot.stops, robot.keep_alives), (1, 1));
        // Re-armed, with the stop taken: the cycle goes on.
        assert!(c.rearm());
        robot.state.acked_seq = robot.seq;
        robot.tick(1.004);
        assert!(matches!(
            c.robot_phase(1.004, &mut robot, &mut rec),
            RobotStep::Ready(_)
        ));
    }

    #[test]
    fn a_short_state_gap_is_a_fault_that_does_not_latch() {
        let (mut c, mut robot) = fixture();
        robot.tick(1.0);
        let p = c.cfg.params;
        let mut rec = CycleRecord::new(1.0, c.mode, c.cmd.q);
        let late = 1.0 + p.robot_stale_s * 1.5;
        let step = c.robot_phase(late, &mut robot, &mut rec);
        assert!(matches!(
            step,
            RobotStep::Done(Some(Mode::Faulted(Reason::RobotStale)))
        ));
        assert_eq!(c.fault.latched, None);
        robot.state.acked_seq = robot.seq;
        robot.tick(late);
        assert!(matches!(
            c.robot_phase(late, &mut robot, &mut rec),
            RobotStep::Ready(_)
        ));
    }

    #[test]
    fn free_drive_follows_the_hand_and_holds() {
        let (mut c, mut robot) = fixture();
        c.set_freedrive(true);
        robot.tick(1.0);
        let q = [0.3, -1.1, 1.4, -1.7, -1.5, 0.1];
        robot.state.actual_q = q;
        let mut rec = CycleRecord::new(1.0, c.mode, c.cmd.q);
        let step = c.robot_phase(1.0, &mut robot, &mut rec);
        assert!(matches!(
            step,
            RobotStep::Done(Some(Mode::Holding(Reason::HandGuided)))
        ));
        assert_eq!((robot.freedrives, rec.q_command, c.cmd.q), (1, q, q));
        assert!(
            !c.cmd.have,
            "a hand-guided arm has no setpoint to go on from"
        );
    }
}
