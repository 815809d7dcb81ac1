//! The dashboard server's commands (port 29999), answered as URControl does.

use super::*;

impl Controller {
    // ---------------------------------------------------------------- dashboard

    /// Answers one dashboard command line (without the line end).
    pub fn dashboard(&mut self, line: &str) -> String {
        let line = line.trim();
        let lower = line.to_ascii_lowercase();
        let v = self.config.version();
        match lower.as_str() {
            "power on" => {
                if matches!(
                    self.safety_mode,
                    SafetyMode::RobotEmergencyStop | SafetyMode::SystemEmergencyStop
                ) {
                    return "Failed to power on: emergency stop active".into();
                }
                if matches!(self.robot_mode, RobotMode::PowerOff | RobotMode::PowerOn) {
                    self.robot_mode = RobotMode::Idle;
                }
                "Powering on".into()
            }
            "power off" => {
                self.stop_program("power off".into());
                self.robot_mode = RobotMode::PowerOff;
                self.motion = Motion::Idle;
                self.qd = [0.0; 6];
                self.qd_int = [0.0; 6];
                "Powering off".into()
            }
            "brake release" => {
                if self.robot_mode == RobotMode::Idle {
                    self.robot_mode = RobotMode::Running;
                }
                "Brake releasing".into()
            }
            "play" => "Failed to execute: play (no program loaded in the simulator)".into(),
            "stop" => {
                self.stop_program("dashboard stop".into());
                "Stopped".into()
            }
            "pause" => "Failed to execute: pause".into(),
            "robotmode" => format!("Robotmode: {}", self.robot_mode.name()),
            "safetymode" => format!("Safetymode: {}", self.safety_mode.name()),
            "safetystatus" => format!("Safetystatus: {}", self.safety_mode.name()),
            "programstate" => {
                let state = if self.runtime == RuntimeState::Playing {
                    "PLAYING"
                } else {
                    "STOPPED"
                };
                let name = match self.program {
                    Program::Mocomp(_) => "mocomp_control",
                    Program::UrRtde(_) => "rtde_control",
                    Program::None => "<unnamed>",
                };
                format!("{state} {name}")
            }
            "running" => format!("Program running: {}", self.runtime == RuntimeState::Playing),
            "unlock protective stop" => {
                if self.safety_mode != SafetyMode::ProtectiveStop {
                    return "Protective stop releasing".into();
                }
                if self.time_s - self.stopped_at_s < self.config.unlock_delay_s {
                    return "Cannot unlock protective stop until 5s after occurrence. Always \
                            inspect cause of protective stop before unlocking"
                        .into();
                }
                self.safety_mode = SafetyMode::Normal;
                self.record_event("protective stop unlocked".into());
                "Protective stop releasing".into()
            }
            "close safety popup" => "closing safety popup".into(),
            "close popup" => "closing popup".into(),
            "restart safety" => {
                if self.safety_mode != SafetyMode::Normal {
                    self.safety_mode = SafetyMode::Normal;
                    self.robot_mode = RobotMode::PowerOff;
                }
                "Restarting safety".into()
            }
            "polyscopeversion" => format!("URSoftware {v} (simulated by mocomp)"),
            "version" => v.to_string(),
            "is in remote control" => "true".into(),
            "get serial number" => self.config.serial.clone(),
            "get robot model" => self.config.model.name().to_ascii_uppercase(),
            "quit" => "Disconnected".into(),
            "shutdown" => "Shutting down".into(),
            "get loaded program" => "No program loaded".into(),
            _ if lower.starts_with("load ") => {
                format!("File not found: {}", line[5..].trim())
            }
            _ => format!("could not understand: '{line}'"),
        }
    }
}
