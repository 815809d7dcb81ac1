//! Bringing a stopped controller back when the operator asks to resume (a re-arm): what the
//! robot's state says must be done, decided without sockets ([`plan`]), then done
//! ([`crate::UrRobot::recover`]).
//!
//! Software does what UR lets a remote client do and the operator has asked for: connect again,
//! unlock a protective stop, start the control program again. It never releases an emergency
//! stop, powers the arm on or releases its brakes: those are done at the cell, by a person who
//! can see the patient (UR's own rule for the emergency stop; for power and brakes, mocomp's:
//! a brake release moves the arm).

use crate::error::UrError;
use mocomp_robot::{RobotFault, RobotMode, RobotState, SafetyMode};

/// What a re-arm does first.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// Nothing: the robot is healthy and the program runs.
    Nothing,
    /// Connect again (the connection closed or the state stream went silent): a fresh
    /// connection uploads the program too.
    Reconnect,
    /// Unlock the protective stop through the dashboard, then start the program again.
    UnlockProtectiveStop,
    /// Start the control program again (the watchdog, a dashboard or pendant stop ended it).
    RestartProgram,
    /// Nothing software may do: the operator must act at the cell first.
    Refuse(Refusal),
}

/// Why a re-arm cannot proceed, and what the operator does about it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Refusal {
    /// An emergency stop is active.
    EmergencyStop,
    /// The arm is not running (powered off, brakes on, booting).
    NotRunning(RobotMode),
    /// Another safety mode (a violation, a fault, safeguard stop).
    Safety(SafetyMode),
}

impl Refusal {
    /// What the operator does before resuming again.
    pub fn advice(self) -> &'static str {
        match self {
            Self::EmergencyStop => {
                "an emergency stop is active: release it, power the arm on and release the brakes \
                 on the teach pendant, then resume"
            }
            Self::NotRunning(_) => {
                "the arm is not running: power it on and release the brakes on the teach pendant \
                 (or the dashboard server's `power on` and `brake release`), then resume"
            }
            Self::Safety(_) => {
                "the controller is in a safety mode software may not clear: clear it on the teach \
                 pendant, then resume"
            }
        }
    }
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::EmergencyStop => write!(f, "emergency stop; {}", self.advice()),
            Self::NotRunning(m) => write!(f, "robot mode {m}; {}", self.advice()),
            Self::Safety(m) => write!(f, "safety mode {m}; {}", self.advice()),
        }
    }
}

/// What a re-arm does, from the newest state (`None`: none yet) and whether the state stream is
/// alive (a state newer than the staleness limit on a connection that has not closed).
pub fn plan(state: Option<&RobotState>, stream_alive: bool) -> Step {
    let Some(s) = state.filter(|_| stream_alive) else {
        return Step::Reconnect;
    };
    match s.fault() {
        None => Step::Nothing,
        Some(RobotFault::Disconnected) => Step::Reconnect,
        Some(RobotFault::EmergencyStop) => Step::Refuse(Refusal::EmergencyStop),
        Some(RobotFault::ProtectiveStop) => Step::UnlockProtectiveStop,
        Some(RobotFault::Safety(m)) => Step::Refuse(Refusal::Safety(m)),
        Some(RobotFault::NotRunning(m)) => Step::Refuse(Refusal::NotRunning(m)),
        Some(RobotFault::ProgramStopped) => Step::RestartProgram,
    }
}

/// Why a re-arm did not bring the robot back.
#[derive(Debug, thiserror::Error)]
pub enum RecoveryError {
    /// A step software may not take: the operator acts at the cell first.
    #[error("re-arming: {0}")]
    Refused(Refusal),
    /// A step failed (the controller unreachable, a dashboard reply other than expected, the
    /// program not starting).
    #[error("re-arming: {step:?} failed: {source}")]
    Failed {
        /// The step.
        step: Step,
        /// Why.
        #[source]
        source: UrError,
    },
}

/// What a re-arm did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Recovered {
    /// Nothing was needed.
    Healthy,
    /// Connected again (the program uploaded and running).
    Reconnected,
    /// The protective stop unlocked and the program running again.
    ProtectiveStopUnlocked,
    /// The program running again.
    ProgramRestarted,
}

impl std::fmt::Display for Recovered {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Healthy => "the robot was healthy",
            Self::Reconnected => "connected again, the control program running",
            Self::ProtectiveStopUnlocked => {
                "protective stop unlocked, the control program running again"
            }
            Self::ProgramRestarted => "the control program running again",
        })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Isometry3;
    use mocomp_robot::RuntimeState;
    use mocomp_robot::state::SAFETY_BIT_EMERGENCY_STOP;

    fn healthy() -> RobotState {
        RobotState {
            program_mode: crate::program::mode::SERVO,
            ..RobotState::at_rest(1.0, [0.0; 6], Isometry3::identity())
        }
    }

    #[test]
    fn each_fault_has_its_recovery_and_what_software_may_not_do_is_refused() {
        let s = healthy();
        assert_eq!(plan(Some(&s), true), Step::Nothing);
        assert_eq!(plan(None, true), Step::Reconnect);
        assert_eq!(plan(Some(&s), false), Step::Reconnect);
        let closed = RobotState {
            connected: false,
            ..s
        };
        assert_eq!(plan(Some(&closed), true), Step::Reconnect);
        let stopped = RobotState {
            runtime_state: RuntimeState::Stopped,
            ..s
        };
        assert_eq!(plan(Some(&stopped), true), Step::RestartProgram);
        let theirs = RobotState {
            program_ours: false,
            ..s
        };
        assert_eq!(plan(Some(&theirs), true), Step::RestartProgram);
        let protective = RobotState {
            safety_mode: SafetyMode::ProtectiveStop,
            runtime_state: RuntimeState::Stopped,
            ..s
        };
        assert_eq!(plan(Some(&protective), true), Step::UnlockProtectiveStop);
        let estop = RobotState {
            safety_status_bits: SAFETY_BIT_EMERGENCY_STOP,
            ..protective
        };
        assert_eq!(
            plan(Some(&estop), true),
            Step::Refuse(Refusal::EmergencyStop)
        );
        let off = RobotState {
            robot_mode: RobotMode::PowerOff,
            runtime_state: RuntimeState::Stopped,
            ..s
        };
        assert_eq!(
            plan(Some(&off), true),
            Step::Refuse(Refusal::NotRunning(RobotMode::PowerOff))
        );
        assert!(
            Refusal::NotRunning(RobotMode::PowerOff)
                .to_string()
                .contains("POWER_OFF")
        );
    }
}
