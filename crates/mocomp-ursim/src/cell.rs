//! The cell's own events, as a person in the room causes them: a protective stop (a bump, a
//! safety plane), the emergency stop pressed and released. A real controller has no network
//! command for these (only the dashboard's `stop`, `power off`, `unlock protective stop`, which
//! the dashboard server simulates); the simulator takes them as text lines, one per line, from
//! whoever stands for the room (a test, `mocomp ursim --cell-stdin`).

use crate::controller::Controller;
use crate::server::SimHandle;
use std::io::BufRead;

/// One event of the cell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CellEvent {
    /// The safety system stops the arm (`protective stop [why]`).
    ProtectiveStop(String),
    /// The emergency stop is pressed (`emergency stop`): the arm stops, the program ends.
    EmergencyStop,
    /// The emergency stop is released (`emergency stop release`): the arm stays powered off.
    EmergencyStopRelease,
}

impl CellEvent {
    /// Parses a line; unknown ones are refused, naming what is understood.
    pub fn parse(line: &str) -> Result<Self, String> {
        let l = line.trim();
        let lower = l.to_ascii_lowercase();
        if lower == "emergency stop" {
            Ok(Self::EmergencyStop)
        } else if lower == "emergency stop release" {
            Ok(Self::EmergencyStopRelease)
        } else if let Some(rest) = lower.strip_prefix("protective stop") {
            let why = l[l.len() - rest.len()..].trim();
            Ok(Self::ProtectiveStop(if why.is_empty() {
                "the cell".into()
            } else {
                why.to_string()
            }))
        } else {
            Err(format!(
                "unknown cell event {l:?}: `protective stop [why]`, `emergency stop` or \
                 `emergency stop release`"
            ))
        }
    }

    /// Lets it happen to the controller.
    pub fn apply(&self, c: &mut Controller) {
        match self {
            Self::ProtectiveStop(why) => c.protective_stop(why.clone()),
            Self::EmergencyStop => c.emergency_stop(),
            Self::EmergencyStopRelease => c.release_emergency_stop(),
        }
    }
}

/// Applies each line of `lines` to the simulator until the input ends; a line that is not an
/// event goes to `refused`, and the rest go on.
pub fn follow(lines: impl BufRead, sim: &SimHandle, mut refused: impl FnMut(String)) {
    for line in lines.lines().map_while(Result::ok) {
        match CellEvent::parse(&line) {
            Ok(e) => sim.with(|c| e.apply(c)),
            Err(why) => refused(why),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::controller::ControllerConfig;
    use mocomp_kin::Model;
    use mocomp_ur::{RobotMode, SafetyMode};

    #[test]
    fn each_event_parses_and_happens_and_an_unknown_one_is_named() {
        assert_eq!(
            CellEvent::parse("  Protective stop  bumped the table "),
            Ok(CellEvent::ProtectiveStop("bumped the table".into()))
        );
        assert_eq!(
            CellEvent::parse("protective stop"),
            Ok(CellEvent::ProtectiveStop("the cell".into()))
        );
        let e = CellEvent::parse("fire alarm").unwrap_err();
        assert!(
            e.contains("fire alarm") && e.contains("emergency stop"),
            "{e}"
        );
        let mut c = Controller::new(ControllerConfig::new(Model::Ur3e));
        CellEvent::parse("protective stop x").unwrap().apply(&mut c);
        assert_eq!(c.safety_mode(), SafetyMode::ProtectiveStop);
        assert_eq!(c.protective_stops(), 1);
        let mut c = Controller::new(ControllerConfig::new(Model::Ur3e));
        CellEvent::EmergencyStop.apply(&mut c);
        assert_eq!(c.safety_mode(), SafetyMode::RobotEmergencyStop);
        CellEvent::EmergencyStopRelease.apply(&mut c);
        assert_eq!(c.safety_mode(), SafetyMode::Normal);
        assert_eq!(c.robot_mode(), RobotMode::PowerOff);
    }
}
