//! `[session]`: the clinical session around the loop (targets, the gate, pulses, the stimulator).

use super::*;

/// `[session]`: the clinical session around `mocomp run`'s loop: the targets, the on-target gate
/// on a robot output, the stimulator's pulses and their log, the calibration's drift monitor.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SessionSection {
    /// The session's targets file (`mocomp targets`, `teach-goal --name`), relative to this
    /// file.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub targets: Option<String>,
    /// The target the loop starts on (a name in `targets`; default: `[goal]`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// Write one CSV row per pulse to this file (relative to this file): its UTC time, the
    /// target, the coil's errors, its pose on the image and distance to the scalp, the output.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pulse_log: Option<String>,
    /// The stimulator's output, % of its maximum, recorded with each pulse whose stimulator does
    /// not say it (a pulse on a robot input says nothing; a STRING `pulse output=65` does).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stimulator_output_pct: Option<f64>,
    /// The robot's digital output that carries the gate (0-7 standard, 8-15 configurable).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gate_output: Option<u32>,
    /// The robot's digital input the stimulator's pulse comes in on (0-17).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pulse_input: Option<u32>,
    /// Publish the gate to the tracker's OpenIGTLink server as STRING messages of this device
    /// (`open`, or `shut: why`), and, without a `pulse_input`, take a STRING `pulse` from it as
    /// a pulse (one source of pulses, never two: each would log the same pulse).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub igtl_device: Option<String>,
    /// The tracker device of a marker on the flange, for the drift monitor (the calibration
    /// marker's `calibrate.device`; none: no drift monitor).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub marker_device: Option<String>,
    /// That marker on the flange, flange_from_marker (default: the calibration file's X; with
    /// the simulated tracker, `tracker.simulated.flange_from_marker`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flange_from_marker: Option<Pose>,
    /// The on-target gate's tolerances and dwell.
    pub gate: mocomp_session::GateParams,
    /// The drift monitor's levels.
    pub drift: mocomp_session::DriftParams,
    /// The simulated world's stimulator (with `robot.simulate`): pulses at `rate_hz` while the
    /// gate output is high.
    pub simulated_stimulator: SimStimulatorSection,
}

/// `[session.simulated_stimulator]`: a stimulator in the simulated world, its trigger wired
/// through the gate output: while the output is high it fires at `rate_hz`, each pulse reported
/// as the session is configured to take it (the robot's input, and an OpenIGTLink STRING).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimStimulatorSection {
    /// Pulses per second while the gate is open (0: no stimulator).
    pub rate_hz: f64,
    /// The output it announces with each pulse over OpenIGTLink (`pulse output=…`, stamped
    /// with its own clock), %; none: a plain `pulse`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output_pct: Option<f64>,
}

impl SessionSection {
    /// The session's parameters.
    pub fn params(&self) -> mocomp_session::SessionParams {
        mocomp_session::SessionParams {
            gate: self.gate,
            drift: self.drift,
            gate_output: self.gate_output,
            pulse_input: self.pulse_input,
        }
    }
}

impl SessionSection {
    /// The session's parameters and the keys that only make sense with others (a gate on the dose needs a coil model).
    pub(super) fn check(&self, coil: &CoilSection) -> Result<(), AppError> {
        self.params()
            .validate()
            .map_err(|e| AppError::Config(format!("session.{e}")))?;
        if self.params().gate.max_dose_error_pct.is_some() && coil.model.is_none() {
            return Err(AppError::Config(
                "session.gate.max_dose_error_pct: the gate judges the dose, which needs \
                 coil.model (a SimNIBS .ccd file)"
                    .into(),
            ));
        }
        Check::range(
            "session.simulated_stimulator.rate_hz",
            self.simulated_stimulator.rate_hz,
            0.0,
            50.0,
            false,
        )?;
        for (key, v) in [
            ("session.stimulator_output_pct", self.stimulator_output_pct),
            (
                "session.simulated_stimulator.output_pct",
                self.simulated_stimulator.output_pct,
            ),
        ] {
            if let Some(v) = v {
                Check::range(key, v, 0.0, 100.0, false)?;
            }
        }
        if self.target.is_some() && self.targets.is_none() {
            return Err(AppError::Config(
                "session.target: needs session.targets (the file it is in)".into(),
            ));
        }
        // A pulse log no pulse can reach stays empty (`session_wiring` names the rest).
        if self.pulse_log.is_some() && self.pulse_input.is_none() && self.igtl_device.is_none() {
            return Err(AppError::Config(
                "session.pulse_log: no pulse can reach it: set session.pulse_input (the robot \
                 input the stimulator's pulse comes in on) or session.igtl_device (pulses as \
                 OpenIGTLink STRING \"pulse\")"
                    .into(),
            ));
        }
        Ok(())
    }
}
