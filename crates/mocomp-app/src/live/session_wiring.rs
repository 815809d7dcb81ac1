//! Whether a configuration's `[session]` is wired so that pulses can be counted and logged:
//! pulses come back on `pulse_input` (a robot input) or, without one, as OpenIGTLink STRING
//! `pulse` messages of `igtl_device`. A gated or simulated stimulator with neither fires unseen
//! (a pulse log with neither is refused as the file is read). Said before a session starts
//! (`config check`, `run`), not found in an empty log afterwards.

use crate::config::Config;

/// Whether pulses have a way back.
fn has_pulse_source(c: &Config) -> bool {
    c.session.pulse_input.is_some() || c.session.igtl_device.is_some()
}

/// The wiring that works but does less than it seems to: each a sentence naming the keys.
pub fn notes(c: &Config) -> Vec<String> {
    let s = &c.session;
    let mut out = Vec::new();
    let stimulating = s.simulated_stimulator.rate_hz > 0.0;
    if !has_pulse_source(c) && (s.gate_output.is_some() || stimulating) {
        out.push(format!(
            "{} but no pulse comes back: pulses are neither counted nor logged (set \
             session.pulse_input or session.igtl_device)",
            match (s.gate_output, stimulating) {
                (Some(o), true) => format!(
                    "session.gate_output = {o} gates a simulated stimulator at {} Hz",
                    s.simulated_stimulator.rate_hz
                ),
                (Some(o), false) => format!("session.gate_output = {o} gates the stimulator"),
                (None, _) => format!(
                    "session.simulated_stimulator fires at {} Hz",
                    s.simulated_stimulator.rate_hz
                ),
            }
        ));
    }
    if stimulating && !c.robot.simulate {
        out.push(
            "session.simulated_stimulator: ignored, the robot is real (robot.simulate = false)"
                .into(),
        );
    }
    if stimulating && s.gate_output.is_none() {
        out.push(
            "session.simulated_stimulator without session.gate_output: it fires whether or not \
             the coil is on target"
                .into(),
        );
    }
    if s.pulse_input.is_some() && s.igtl_device.is_some() {
        out.push(
            "session.pulse_input and session.igtl_device: pulses are taken from the input only \
             (the device is told the gate)"
                .into(),
        );
    }
    out
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn with(text: &str) -> Config {
        Config::parse("t.toml", text).unwrap()
    }

    #[test]
    fn a_gated_stimulator_with_no_way_back_for_its_pulses_is_named() {
        let c = with("[session]\ngate_output = 7\n[session.simulated_stimulator]\nrate_hz = 5.0\n");
        let n = notes(&c);
        assert_eq!(n.len(), 1, "{n:?}");
        assert!(
            n[0].contains("session.gate_output = 7")
                && n[0].contains("5 Hz")
                && n[0].contains("session.pulse_input"),
            "{n:?}"
        );
        // Wired back through the robot's input: nothing to say.
        let ok = with(
            "[session]\ngate_output = 7\npulse_input = 0\n[session.simulated_stimulator]\nrate_hz = 5.0\n",
        );
        assert!(notes(&ok).is_empty(), "{:?}", notes(&ok));
        let igtl = with("[session]\ngate_output = 7\nigtl_device = \"MocompGate\"\n");
        assert!(notes(&igtl).is_empty(), "{:?}", notes(&igtl));
    }

    #[test]
    fn a_pulse_log_no_pulse_can_reach_is_refused_by_its_key() {
        // Refused as the file is read, naming the file and the key.
        let text = "[session]\npulse_log = \"p.csv\"\ngate_output = 7\n";
        let e = Config::parse("t.toml", text).unwrap_err().to_string();
        assert!(
            e.contains("t.toml")
                && e.contains("session.pulse_log")
                && e.contains("session.pulse_input"),
            "{e}"
        );
        assert!(
            Config::parse(
                "t.toml",
                "[session]\npulse_log = \"p.csv\"\npulse_input = 0\n"
            )
            .is_ok()
        );
    }

    #[test]
    fn a_stimulator_without_a_gate_or_a_simulated_robot_is_named() {
        let c = with("[session]\npulse_input = 0\n[session.simulated_stimulator]\nrate_hz = 5.0\n");
        let n = notes(&c);
        assert!(n.iter().any(|l| l.contains("whether or not")), "{n:?}");
        let real = with(
            "[robot]\nsimulate = false\n[session]\npulse_input = 0\ngate_output = 7\n[session.simulated_stimulator]\nrate_hz = 5.0\n",
        );
        assert!(
            notes(&real).iter().any(|l| l.contains("ignored")),
            "{:?}",
            notes(&real)
        );
    }
}
