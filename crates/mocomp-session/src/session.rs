//! The session beside the loop: which target is selected, the on-target gate on each cycle's
//! measured coil, the pulses (a robot digital input's rising edge, or a message), and the drift
//! monitor, whose verdict it latches.
//!
//! The driver calls [`Session::cycle`] after each loop cycle with its record and the robot's
//! digital inputs, [`Session::marker`] with each sample of a marker on the coil, and passes on
//! what it returns: the gate's level to the robot's output, the calibration's verdict to the
//! loop, the pulses and events to the log. Everything here is `Copy` and allocation-free, so it
//! runs on the loop's thread; the target's name is looked up by index where the pulse is written.

use crate::drift::{Drift, DriftMonitor, DriftParams};
use crate::gate::{Gate, GateEvent, GateInputs, GateParams, GateState, Shut};
use mocomp_control::{CycleRecord, Mode};
use mocomp_geom::nalgebra::Isometry3;

/// The session's settings.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SessionParams {
    /// The on-target gate.
    pub gate: GateParams,
    /// The drift monitor.
    pub drift: DriftParams,
    /// The robot's digital output that carries the gate (0-7 standard, 8-15 configurable;
    /// `None`: the gate drives no output).
    pub gate_output: Option<u32>,
    /// The robot's digital input the stimulator's pulse comes in on (0-17; `None`: pulses come
    /// as messages only).
    pub pulse_input: Option<u32>,
}

impl SessionParams {
    /// Checks the outputs and inputs exist and the tolerances are positive; names the key.
    pub fn validate(&self) -> Result<(), String> {
        if let Some(b) = self.gate_output
            && b > 15
        {
            return Err(format!(
                "gate_output = {b}: RTDE sets outputs 0-7 (standard) and 8-15 (configurable)"
            ));
        }
        if let Some(b) = self.pulse_input
            && b > 17
        {
            return Err(format!(
                "pulse_input = {b}: inputs are 0-7 (standard), 8-15 (configurable), 16-17 (tool)"
            ));
        }
        let g = &self.gate;
        for (key, v) in [
            ("gate.position_tolerance_m", g.position_tolerance_m),
            ("gate.angle_tolerance_rad", g.angle_tolerance_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{key} = {v}: must be finite and > 0"));
            }
        }
        if let Some(m) = g.max_dose_error_pct
            && !(m.is_finite() && m > 0.0 && m <= 100.0)
        {
            return Err(format!(
                "gate.max_dose_error_pct = {m}: must be a percentage in (0, 100]"
            ));
        }
        if !(g.dwell_s.is_finite() && g.dwell_s >= 0.0) {
            return Err(format!(
                "gate.dwell_s = {}: must be finite and >= 0",
                g.dwell_s
            ));
        }
        let d = &self.drift;
        for (key, v) in [
            ("drift.warning_m", d.warning_m),
            ("drift.limit_m", d.limit_m),
            ("drift.warning_rad", d.warning_rad),
            ("drift.limit_rad", d.limit_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{key} = {v}: must be finite and > 0"));
            }
        }
        if !(d.warning_m <= d.limit_m && d.warning_rad <= d.limit_rad) {
            return Err("drift: each warning level must be at most its limit".into());
        }
        Ok(())
    }
}

/// One pulse, as the loop's thread knows it (the target by index).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PulseAt {
    /// Loop time, s.
    pub t_s: f64,
    /// The selected target's index.
    pub target: usize,
    /// The measured coil's position error against the target, m (NaN: no head estimate).
    pub position_error_m: f64,
    /// Its angle error, rad.
    pub angle_error_rad: f64,
    /// The head's speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// The gate when the pulse came (the level the stimulator's trigger saw).
    pub gate: GateState,
    /// The measured coil in the head marker's frame (`head_from_coil`), when the head was
    /// known: where the pulse landed.
    pub coil: Option<Isometry3<f64>>,
    /// The stimulator's own time of the pulse (Unix seconds, UTC), when it gave one.
    pub stimulator_unix_s: Option<f64>,
    /// The stimulator's output, % of its maximum, when it said.
    pub output_pct: Option<f64>,
    /// The dose the measured coil gave at the target, V/m and % of the planned (NaN: none).
    pub dose: (f64, f64),
}

/// A pulse a message announced (an OpenIGTLink STRING `pulse`): when it came, on the loop's
/// clock, and what the stimulator said of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Announced {
    /// When it was received, loop time, s.
    pub t_s: f64,
    /// The stimulator's own time of the pulse (Unix seconds, UTC), when its message carried one.
    pub stimulator_unix_s: Option<f64>,
    /// Its output, % of the stimulator's maximum, when the message said.
    pub output_pct: Option<f64>,
}

impl Announced {
    /// The announcement in a STRING's `text`: `pulse`, then optionally `output=<percent>` (any
    /// case, separated by spaces); `None` when the text is no pulse (another message on the
    /// device, or an output that is no percentage, which must not pass as a pulse of unknown
    /// strength).
    pub fn parse(text: &str, t_s: f64, stimulator_unix_s: Option<f64>) -> Option<Self> {
        let mut words = text.split_whitespace();
        if !words.next()?.eq_ignore_ascii_case("pulse") {
            return None;
        }
        let mut output_pct = None;
        for w in words {
            let (key, value) = w.split_once('=')?;
            if !key.eq_ignore_ascii_case("output") {
                return None;
            }
            let v: f64 = value.trim_end_matches('%').parse().ok()?;
            if !(0.0..=100.0).contains(&v) {
                return None;
            }
            output_pct = Some(v);
        }
        Some(Self {
            t_s,
            stimulator_unix_s,
            output_pct,
        })
    }
}

/// What one cycle of the session produced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Step {
    /// The gate opened or shut.
    pub gate_event: Option<GateEvent>,
    /// Whether the gate is open now (the output's level).
    pub gate_open: bool,
    /// A pulse came in on the input.
    pub pulse: Option<PulseAt>,
}

/// The session's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Session {
    params: SessionParams,
    gate: Gate,
    drift: DriftMonitor,
    target: usize,
    /// A new target was selected and the loop has not yet left tracking the old one.
    switching: bool,
    /// The calibration's offset once the monitor called it invalid (latched).
    invalid: Option<(f64, f64)>,
    /// The pulse input's level at the last cycle.
    pulse_level: Option<bool>,
    /// The last cycle's time, coil error and head speed (an external pulse's record).
    last: (f64, (f64, f64), (f64, f64)),
    /// The last cycle's measured coil on the head.
    last_coil: Option<Isometry3<f64>>,
    /// The last cycle's dose, V/m and % of the planned.
    last_dose: (f64, f64),
}

impl Session {
    /// A session on target `target`, with a calibration whose marker pose is uncertain by
    /// `sigma` (m, rad; 1σ).
    pub fn new(params: SessionParams, sigma: (f64, f64), target: usize) -> Self {
        Self {
            params,
            gate: Gate::new(params.gate),
            drift: DriftMonitor::new(params.drift, sigma.0, sigma.1),
            target,
            switching: false,
            invalid: None,
            pulse_level: None,
            last: (f64::NAN, (f64::NAN, f64::NAN), (0.0, 0.0)),
            last_coil: None,
            last_dose: (f64::NAN, f64::NAN),
        }
    }

    /// The settings.
    pub fn params(&self) -> &SessionParams {
        &self.params
    }

    /// The selected target's index.
    pub fn target(&self) -> usize {
        self.target
    }

    /// Selects another target (the caller gives the loop its goal). The gate stays shut until
    /// the loop has left tracking the old target for its path and come back on the new one.
    pub fn select(&mut self, target: usize) {
        self.target = target;
        self.switching = true;
    }

    /// The gate now.
    pub fn gate(&self) -> GateState {
        self.gate.state()
    }

    /// The calibration's offset (m, rad) once the drift monitor called it invalid: the loop must
    /// hold until a new calibration ([`Self::recalibrated`]).
    pub fn calibration_invalid(&self) -> Option<(f64, f64)> {
        self.invalid
    }

    /// The drift monitor's verdict now.
    pub fn drift(&self) -> Drift {
        self.drift.state()
    }

    /// A new calibration (uncertain by `sigma`): the monitor starts again.
    pub fn recalibrated(&mut self, sigma: (f64, f64)) {
        self.drift = DriftMonitor::new(self.params.drift, sigma.0, sigma.1);
        self.invalid = None;
    }

    /// After a loop cycle: its record and the robot's digital inputs (`None`: not known).
    pub fn cycle(&mut self, rec: &CycleRecord, digital_inputs: Option<u64>) -> Step {
        if self.switching && rec.mode != Mode::Tracking {
            // The loop took the new goal: from here, tracking means tracking it.
            self.switching = false;
        }
        let before = self.gate.state();
        let tracking = rec.mode == Mode::Tracking && !self.switching;
        let error = rec.coil_error.0.is_finite().then_some(rec.coil_error);
        let gate_event = self.gate.update(
            rec.t,
            &GateInputs {
                tracking,
                error,
                dose_pct: rec.dose_pct,
            },
        );
        self.last = (rec.t, rec.coil_error, rec.head_speed);
        self.last_coil = rec.coil_now;
        self.last_dose = (rec.dose_v_per_m, rec.dose_pct);
        let level = match (self.params.pulse_input, digital_inputs) {
            (Some(bit), Some(bits)) => Some(bits & (1 << bit) != 0),
            _ => None,
        };
        let rising = matches!((self.pulse_level, level), (Some(false), Some(true)));
        self.pulse_level = level;
        Step {
            gate_event,
            gate_open: self.gate.is_open(),
            pulse: rising.then(|| self.pulse_with(rec.t, before, None, None)),
        }
    }

    /// A pulse announced by a message (an OpenIGTLink STRING "pulse"): the coil as the last
    /// cycle measured it, the gate as it is, what the stimulator said.
    pub fn pulse(&self, a: &Announced) -> PulseAt {
        self.pulse_with(a.t_s, self.gate.state(), a.stimulator_unix_s, a.output_pct)
    }

    fn pulse_with(
        &self,
        t_s: f64,
        gate: GateState,
        stimulator_unix_s: Option<f64>,
        output_pct: Option<f64>,
    ) -> PulseAt {
        let (_, (d, a), speed) = self.last;
        PulseAt {
            t_s,
            target: self.target,
            position_error_m: d,
            angle_error_rad: a,
            head_speed: speed,
            gate,
            coil: self.last_coil,
            stimulator_unix_s,
            output_pct,
            dose: self.last_dose,
        }
    }

    /// A sample of the coil's marker seen by the tracker and where the robot and the
    /// calibration put it (both in the base frame), at its acquisition time `t_s`. Returns the
    /// monitor's verdict when it changed; an invalid calibration is latched.
    pub fn marker(
        &mut self,
        t_s: f64,
        base_from_marker_tracked: &Isometry3<f64>,
        base_from_marker_robot: &Isometry3<f64>,
    ) -> Option<Drift> {
        let changed = self
            .drift
            .update(t_s, base_from_marker_tracked, base_from_marker_robot);
        if let (Drift::Invalid(m, a), None) = (self.drift.state(), self.invalid) {
            self.invalid = Some((m, a));
        }
        changed
    }
}

/// Why the gate is shut, in words (the log's and the console's).
pub fn shut_reason(s: &Shut) -> String {
    match s {
        Shut::Dwelling(_) => "dwelling".into(),
        Shut::PositionError(d) => format!("position error {:.2} mm", d * 1e3),
        Shut::AngleError(a) => format!("angle error {:.2} deg", a.to_degrees()),
        Shut::DoseError(pct) => format!("dose {pct:.1} % of the planned"),
        Shut::NoDose => "no dose".into(),
        Shut::NotTracking => "not tracking".into(),
        Shut::NoHead => "no head estimate".into(),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn rec(t: f64, mode: Mode, err: f64) -> CycleRecord {
        let mut r = CycleRecord::new(t, mode, [0.0; 6]);
        r.coil_error = (err, 0.0);
        r.head_speed = (0.01, 0.0);
        r.coil_now = Some(Isometry3::translation(err, 0.0, 0.1));
        r
    }

    fn params() -> SessionParams {
        SessionParams {
            pulse_input: Some(3),
            gate_output: Some(7),
            ..SessionParams::default()
        }
    }

    #[test]
    fn a_pulse_is_a_rising_edge_logged_with_the_gate_the_stimulator_saw() {
        let mut s = Session::new(params(), (0.0, 0.0), 0);
        let mut pulses = Vec::new();
        let mut t = 0.0;
        for k in 0..200 {
            t = k as f64 * 0.002;
            // The input is high for 3 cycles from 0.2 s: one pulse, not three.
            let high = (100..103).contains(&k);
            let step = s.cycle(&rec(t, Mode::Tracking, 0.0005), Some(u64::from(high) << 3));
            pulses.extend(step.pulse);
        }
        assert_eq!(pulses.len(), 1, "{pulses:?}");
        assert_eq!(pulses[0].gate, GateState::Open);
        assert!((pulses[0].t_s - 0.2).abs() < 1e-9);
        assert_eq!(pulses[0].position_error_m, 0.0005);
        // Where it landed: the coil that cycle measured; a robot input says nothing of the
        // stimulator's time or output.
        assert_eq!(
            pulses[0].coil,
            Some(Isometry3::translation(0.0005, 0.0, 0.1))
        );
        assert_eq!(
            (pulses[0].stimulator_unix_s, pulses[0].output_pct),
            (None, None)
        );
        // Another bit changes nothing; an unknown input level no edge.
        assert!(
            s.cycle(&rec(t, Mode::Tracking, 0.0), Some(1 << 2))
                .pulse
                .is_none()
        );
        assert!(s.cycle(&rec(t, Mode::Tracking, 0.0), None).pulse.is_none());
        assert!(
            s.cycle(&rec(t, Mode::Tracking, 0.0), Some(1 << 3))
                .pulse
                .is_none()
        );
        // An off-target pulse is logged, with why the gate was shut.
        s.cycle(&rec(t, Mode::Tracking, 0.004), Some(0));
        let p = s
            .cycle(&rec(t, Mode::Tracking, 0.004), Some(1 << 3))
            .pulse
            .unwrap();
        assert_eq!(p.gate, GateState::Shut(Shut::PositionError(0.004)));
    }

    #[test]
    fn an_announced_pulse_keeps_what_the_stimulator_said_and_the_last_coil() {
        let mut s = Session::new(SessionParams::default(), (0.0, 0.0), 0);
        s.cycle(&rec(1.0, Mode::Tracking, 0.002), None);
        let a = Announced::parse("PULSE output=62.5", 1.01, Some(1.8e9)).unwrap();
        let p = s.pulse(&a);
        assert_eq!(p.t_s, 1.01);
        assert_eq!(p.output_pct, Some(62.5));
        assert_eq!(p.stimulator_unix_s, Some(1.8e9));
        assert_eq!(p.coil, Some(Isometry3::translation(0.002, 0.0, 0.1)));
        assert_eq!(p.position_error_m, 0.002);
        // Plain "pulse", a percent sign, spaces around: pulses; anything else is not one.
        assert_eq!(
            Announced::parse("  pulse ", 0.0, None).unwrap().output_pct,
            None
        );
        assert_eq!(
            Announced::parse("pulse output=70%", 0.0, None)
                .unwrap()
                .output_pct,
            Some(70.0)
        );
        for not in [
            "",
            "pulsed",
            "gate open",
            "pulse output=",
            "pulse output=abc",
            "pulse output=120",
            "pulse output=-1",
            "pulse output=NaN",
            "pulse power=50",
            "pulse 50",
        ] {
            assert_eq!(Announced::parse(not, 0.0, None), None, "{not:?}");
        }
    }

    #[test]
    fn after_a_switch_the_gate_stays_shut_until_the_loop_has_taken_the_new_target() {
        let mut s = Session::new(params(), (0.0, 0.0), 0);
        for k in 0..100 {
            s.cycle(&rec(k as f64 * 0.002, Mode::Tracking, 0.0), Some(0));
        }
        assert!(s.gate().eq(&GateState::Open));
        s.select(1);
        // The loop's record of the cycle before it took the goal still says "tracking", near
        // the old target: the gate shuts all the same.
        let step = s.cycle(&rec(0.2, Mode::Tracking, 0.0), Some(0));
        assert_eq!(step.gate_event, Some(GateEvent::Shut(Shut::NotTracking)));
        for k in 0..200 {
            let step = s.cycle(&rec(0.202 + k as f64 * 0.002, Mode::Tracking, 0.0), Some(0));
            assert!(!step.gate_open);
        }
        // The path, then tracking the new target: open after the dwell.
        s.cycle(&rec(0.7, Mode::Approaching, 0.01), Some(0));
        let mut opened = None;
        for k in 0..100 {
            let t = 0.702 + k as f64 * 0.002;
            if s.cycle(&rec(t, Mode::Tracking, 0.0), Some(0)).gate_event == Some(GateEvent::Opened)
            {
                opened = Some(t);
            }
        }
        assert!((opened.unwrap() - 0.802).abs() < 0.003, "{opened:?}");
        assert_eq!(s.target(), 1);
    }

    #[test]
    fn an_invalid_calibration_is_latched_until_recalibrated() {
        let mut s = Session::new(params(), (5e-5, 3e-4), 0);
        let at = Isometry3::translation(0.3, 0.0, 0.2);
        let bumped = Isometry3::translation(0.303, 0.0, 0.2);
        for k in 0..60 {
            s.marker(k as f64 / 60.0, &bumped, &at);
        }
        let (m, _) = s.calibration_invalid().unwrap();
        assert!(m > 0.002, "{m}");
        // The offset going away again (the camera knocked back?) does not make it valid.
        for k in 60..300 {
            s.marker(k as f64 / 60.0, &at, &at);
        }
        assert_eq!(s.drift(), Drift::Ok);
        assert!(s.calibration_invalid().is_some());
        s.recalibrated((5e-5, 3e-4));
        assert_eq!(s.calibration_invalid(), None);
    }

    #[test]
    fn the_settings_name_what_is_wrong() {
        assert!(params().validate().is_ok());
        let mut p = params();
        p.gate_output = Some(16);
        assert!(p.validate().unwrap_err().contains("gate_output"));
        let mut p = params();
        p.pulse_input = Some(18);
        assert!(p.validate().unwrap_err().contains("pulse_input"));
        let mut p = params();
        p.gate.dwell_s = f64::NAN;
        assert!(p.validate().unwrap_err().contains("gate.dwell_s"));
        let mut p = params();
        p.drift.warning_m = 0.01;
        assert!(p.validate().unwrap_err().contains("warning level"));
        for bad in [0.0, -1.0, 150.0, f64::NAN] {
            let mut p = params();
            p.gate.max_dose_error_pct = Some(bad);
            let e = p.validate().unwrap_err();
            assert!(e.contains("gate.max_dose_error_pct"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_pulse_carries_the_dose_of_the_cycle_it_fell_in_and_the_gate_judges_it() {
        let p = SessionParams {
            gate: GateParams {
                max_dose_error_pct: Some(3.0),
                ..GateParams::default()
            },
            ..params()
        };
        let mut s = Session::new(p, (0.0, 0.0), 0);
        let dosed = |t: f64, pct: f64| {
            let mut r = rec(t, Mode::Tracking, 0.0005);
            (r.dose_v_per_m, r.dose_pct) = (1.2 * pct, pct);
            r
        };
        for k in 0..100 {
            s.cycle(&dosed(k as f64 * 0.002, 99.0), Some(0));
        }
        assert_eq!(s.gate(), GateState::Open);
        let on = s.cycle(&dosed(0.2, 98.5), Some(1 << 3)).pulse.unwrap();
        assert_eq!(on.dose, (1.2 * 98.5, 98.5));
        assert_eq!(on.gate, GateState::Open);
        // The coil lifted: the pose within its tolerances, the dose not; the pulse that comes
        // anyway is recorded with its dose and the gate's reason.
        s.cycle(&dosed(0.202, 95.0), Some(0));
        let off = s.cycle(&dosed(0.204, 95.0), Some(1 << 3)).pulse.unwrap();
        assert_eq!(off.dose.1, 95.0);
        assert_eq!(off.gate, GateState::Shut(Shut::DoseError(95.0)));
        assert_eq!(
            shut_reason(&Shut::DoseError(95.0)),
            "dose 95.0 % of the planned"
        );
        // An announced pulse takes the last cycle's dose.
        let a = Announced::parse("pulse", 0.205, None).unwrap();
        assert_eq!(s.pulse(&a).dose.1, 95.0);
    }
}
