//! The pulse log: one row per stimulator pulse, with where the coil was.
//!
//! Each pulse (a robot digital input edge, or an OpenIGTLink STRING "pulse") is written with its
//! time, the target, the coil's position and angle error against it (the measured coil, as the
//! gate judges), the head's speed and whether the gate was open. A pulse while the gate is shut
//! is written too, marked as such: the record must show every pulse the patient received.

use crate::gate::GateState;
use crate::session::{PulseAt, shut_reason};
use std::io::Write;

/// One pulse.
#[derive(Debug, Clone, PartialEq)]
pub struct Pulse {
    /// Loop time of the pulse, s.
    pub t_s: f64,
    /// The target selected.
    pub target: String,
    /// The measured coil's position error against the target, m (NaN: no head estimate).
    pub position_error_m: f64,
    /// Its angle error, rad.
    pub angle_error_rad: f64,
    /// The head's speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// The gate when the pulse came.
    pub gate: GateState,
}

/// The log's columns.
pub const HEADER: [&str; 8] = [
    "t_s",
    "target",
    "position_error_mm",
    "angle_error_deg",
    "head_speed_mm_s",
    "head_speed_deg_s",
    "gate",
    "why_shut",
];

/// Writes pulses as CSV (on the `csv` crate: a target name with a comma is quoted).
#[derive(Debug)]
pub struct PulseLog<W: Write> {
    w: csv::Writer<W>,
}

impl Pulse {
    /// The pulse the loop's thread saw, with its target's name.
    pub fn named(at: &PulseAt, target: &str) -> Self {
        Self {
            t_s: at.t_s,
            target: target.to_string(),
            position_error_m: at.position_error_m,
            angle_error_rad: at.angle_error_rad,
            head_speed: at.head_speed,
            gate: at.gate,
        }
    }
}

impl<W: Write> PulseLog<W> {
    /// A log writing its header to `out`.
    pub fn new(out: W) -> Result<Self, csv::Error> {
        let mut w = csv::Writer::from_writer(out);
        w.write_record(HEADER)?;
        Ok(Self { w })
    }

    /// Writes one pulse (and flushes: a pulse must not be lost with a crash).
    pub fn write(&mut self, p: &Pulse) -> Result<(), csv::Error> {
        let (gate, why) = match p.gate {
            GateState::Open => ("open", String::new()),
            GateState::Shut(s) => ("shut", shut_reason(&s)),
        };
        self.w.write_record([
            format!("{:.4}", p.t_s),
            p.target.clone(),
            format!("{:.3}", p.position_error_m * 1e3),
            format!("{:.3}", p.angle_error_rad.to_degrees()),
            format!("{:.2}", p.head_speed.0 * 1e3),
            format!("{:.2}", p.head_speed.1.to_degrees()),
            gate.to_string(),
            why,
        ])?;
        self.w.flush()?;
        Ok(())
    }

    /// The writer back.
    pub fn into_inner(self) -> Result<W, csv::Error> {
        self.w.into_inner().map_err(|e| e.into_error().into())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::gate::Shut;

    #[test]
    fn every_pulse_is_a_row_in_units_with_a_shut_gate_marked_and_why() {
        let mut log = PulseLog::new(Vec::new()).unwrap();
        log.write(&Pulse {
            t_s: 12.5,
            target: "hotspot, APB".into(),
            position_error_m: 0.0012,
            angle_error_rad: 0.5f64.to_radians(),
            head_speed: (0.02, 0.1),
            gate: GateState::Open,
        })
        .unwrap();
        log.write(&Pulse {
            t_s: 13.0,
            target: "r0c1".into(),
            position_error_m: 0.004,
            angle_error_rad: 0.0,
            head_speed: (0.0, 0.0),
            gate: GateState::Shut(Shut::PositionError(0.004)),
        })
        .unwrap();
        let text = String::from_utf8(log.into_inner().unwrap()).unwrap();
        let mut r = csv::Reader::from_reader(text.as_bytes());
        assert_eq!(r.headers().unwrap().iter().collect::<Vec<_>>(), HEADER);
        let rows: Vec<csv::StringRecord> = r.records().map(Result::unwrap).collect();
        assert_eq!(&rows[0][1], "hotspot, APB");
        assert_eq!(&rows[0][2], "1.200");
        assert_eq!(&rows[0][3], "0.500");
        assert_eq!(&rows[0][4], "20.00");
        assert_eq!(&rows[0][6], "open");
        assert_eq!(&rows[1][6], "shut");
        assert_eq!(&rows[1][7], "position error 4.00 mm");
    }
}
