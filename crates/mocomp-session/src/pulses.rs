//! The pulse log: one row per stimulator pulse, with where the coil was and when.
//!
//! Each pulse (a robot digital input edge, or an OpenIGTLink STRING "pulse") is written with its
//! loop time and its UTC time (ISO 8601, to line it up with EMG or EEG recorded on other
//! machines), the stimulator's own time when it gave one, the target, the coil's position and
//! angle error against it (the measured coil, as the gate judges), the coil's distance to the
//! scalp, the stimulator's output, the head's speed, whether the gate was open, and the coil's
//! pose in the image's coordinates as SimNIBS writes it (`matsimnibs`, mm), and, with a coil
//! model, the dose the coil gave at the target (V/m, and % of the planned). A pulse while the
//! gate is shut is written too, marked as such: the record must show every pulse the patient
//! received.
//!
//! The log is read back ([`read_log`]) by the session's exports; every field that does not
//! parse is named by line and column.

use crate::gate::GateState;
use crate::session::{PulseAt, shut_reason};
use mocomp_control::HeadModel;
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Point3};
use std::io::Write;
use time::OffsetDateTime;
use time::format_description::well_known::Rfc3339;

/// One pulse, as the log records it.
#[derive(Debug, Clone, PartialEq)]
pub struct Pulse {
    /// Loop time of the pulse, s.
    pub t_s: f64,
    /// Its UTC time, Unix seconds (`None`: the loop's clock was not yet tied to UTC).
    pub utc_unix_s: Option<f64>,
    /// The stimulator's own time of it, Unix seconds, when it gave one.
    pub stimulator_unix_s: Option<f64>,
    /// The target selected.
    pub target: String,
    /// The measured coil's position error against the target, m (NaN: no head estimate).
    pub position_error_m: f64,
    /// Its angle error, rad.
    pub angle_error_rad: f64,
    /// The coil's centre's distance to the scalp, m (negative inside; NaN: no head estimate).
    pub scalp_distance_m: f64,
    /// The stimulator's output, % of its maximum, when known.
    pub output_pct: Option<f64>,
    /// The head's speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// Whether the gate was open when the pulse came.
    pub gate_open: bool,
    /// Why the gate was shut (empty when open).
    pub why_shut: String,
    /// The measured coil in the image's frame (RAS; SimNIBS's coil axes), when the head was known.
    pub image_from_coil: Option<Isometry3<f64>>,
    /// The dose the coil gave at the target, V/m (NaN: no coil model, plan or head estimate).
    pub dose_v_per_m: f64,
    /// The dose, % of the target's planned dose (NaN alike).
    pub dose_pct: f64,
}

/// The columns every log has (a log written before the dose lacks the rest).
const REQUIRED: usize = 13;

/// The log's columns.
pub const HEADER: [&str; 15] = [
    "t_s",
    "utc",
    "stimulator_time",
    "target",
    "position_error_mm",
    "angle_error_deg",
    "scalp_distance_mm",
    "output_pct",
    "head_speed_mm_s",
    "head_speed_deg_s",
    "gate",
    "why_shut",
    "matsimnibs",
    "dose_v_per_m",
    "dose_pct",
];

/// What turns a pulse the loop saw into the log's row: the clocks, the image, the head.
#[derive(Debug, Clone)]
pub struct Recorder {
    /// UTC (Unix seconds) minus the loop's time, once the loop's clock is known.
    pub utc_minus_loop_s: Option<f64>,
    /// The image in the head marker's frame (the registration's, or the configured one).
    pub head_from_image: Isometry3<f64>,
    /// The head the coil's distance to the scalp is measured on (head marker's frame).
    pub head: HeadModel,
    /// The stimulator's output when its pulse does not say (the configured one), %.
    pub output_pct: Option<f64>,
}

impl Recorder {
    /// The row of the pulse `at` on the target named `target`.
    pub fn row(&self, at: &PulseAt, target: &str) -> Pulse {
        let (gate_open, why_shut) = match at.gate {
            GateState::Open => (true, String::new()),
            GateState::Shut(s) => (false, shut_reason(&s)),
        };
        Pulse {
            t_s: at.t_s,
            utc_unix_s: self.utc_minus_loop_s.map(|d| at.t_s + d),
            stimulator_unix_s: at.stimulator_unix_s,
            target: target.to_string(),
            position_error_m: at.position_error_m,
            angle_error_rad: at.angle_error_rad,
            scalp_distance_m: at.coil.map_or(f64::NAN, |c| {
                self.head.distance(&Point3::from(c.translation.vector))
            }),
            output_pct: at.output_pct.or(self.output_pct),
            head_speed: at.head_speed,
            gate_open,
            why_shut,
            image_from_coil: at.coil.map(|c| self.head_from_image.inv_mul(&c)),
            dose_v_per_m: at.dose.0,
            dose_pct: at.dose.1,
        }
    }
}

/// A time as ISO 8601 (RFC 3339) UTC to the microsecond, e.g. `2026-12-06T09:14:03.250117Z`.
pub fn iso8601(unix_s: f64) -> String {
    let us = (unix_s * 1e6).round();
    if !us.is_finite() {
        return String::new();
    }
    // Beyond the years 0-9999 RFC 3339 has no form; such a time is no pulse's.
    OffsetDateTime::from_unix_timestamp_nanos(us as i128 * 1000)
        .ok()
        .and_then(|t| t.format(&Rfc3339).ok())
        .unwrap_or_default()
}

/// An ISO 8601 (RFC 3339) time back to Unix seconds.
pub fn parse_iso8601(s: &str) -> Option<f64> {
    let t = OffsetDateTime::parse(s.trim(), &Rfc3339).ok()?;
    Some(t.unix_timestamp_nanos() as f64 / 1e9)
}

/// A pose as SimNIBS's `matsimnibs`: the 4×4 matrix in mm, row by row.
pub fn matsimnibs(p: &Isometry3<f64>) -> [f64; 16] {
    let mut m = p.to_homogeneous();
    for r in 0..3 {
        m[(r, 3)] *= 1e3;
    }
    let mut out = [0.0; 16];
    for (i, v) in out.iter_mut().enumerate() {
        *v = m[(i / 4, i % 4)];
    }
    out
}

/// Writes pulses as CSV (on the `csv` crate: a target name with a comma is quoted).
#[derive(Debug)]
pub struct PulseLog<W: Write> {
    w: csv::Writer<W>,
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.filter(|v| v.is_finite())
        .map(|v| format!("{v:.digits$}"))
        .unwrap_or_default()
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
        let matrix = p
            .image_from_coil
            .map(|c| {
                matsimnibs(&c)
                    .iter()
                    .map(|v| format!("{v:.6}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .unwrap_or_default();
        self.w.write_record([
            format!("{:.4}", p.t_s),
            p.utc_unix_s.map(iso8601).unwrap_or_default(),
            p.stimulator_unix_s.map(iso8601).unwrap_or_default(),
            p.target.clone(),
            format!("{:.3}", p.position_error_m * 1e3),
            format!("{:.3}", p.angle_error_rad.to_degrees()),
            format!("{:.3}", p.scalp_distance_m * 1e3),
            opt(p.output_pct, 1),
            format!("{:.2}", p.head_speed.0 * 1e3),
            format!("{:.2}", p.head_speed.1.to_degrees()),
            if p.gate_open { "open" } else { "shut" }.to_string(),
            p.why_shut.clone(),
            matrix,
            opt(Some(p.dose_v_per_m), 3),
            opt(Some(p.dose_pct), 2),
        ])?;
        self.w.flush()?;
        Ok(())
    }

    /// The writer back.
    pub fn into_inner(self) -> Result<W, csv::Error> {
        self.w.into_inner().map_err(|e| e.into_error().into())
    }
}

/// What is wrong with a pulse log read back.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PulseLogError {
    /// Not CSV, or a row of the wrong length.
    #[error("{file}:{line}: {detail}")]
    Csv {
        /// The file.
        file: String,
        /// Its line (1-based).
        line: u64,
        /// The CSV reader's message.
        detail: String,
    },
    /// The header lacks a column this version writes (an older log, or another file).
    #[error("{file}: no column {column:?} (a pulse log of this mocomp has: {expected})")]
    Column {
        /// The file.
        file: String,
        /// The column.
        column: &'static str,
        /// The columns expected.
        expected: String,
    },
    /// A field that does not parse.
    #[error("{file}:{line}: column {column}: {value:?} {why}")]
    Field {
        /// The file.
        file: String,
        /// Its line (1-based).
        line: u64,
        /// The column.
        column: &'static str,
        /// The text.
        value: String,
        /// What it should be.
        why: &'static str,
    },
}

/// Reads a pulse log's text (`file` names it in errors) back into its pulses. Empty fields are
/// what the writer leaves for unknowns: NaN, or `None`; a log from before the dose columns
/// reads with no dose.
pub fn read_log(file: &str, text: &str) -> Result<Vec<Pulse>, PulseLogError> {
    let mut r = csv::Reader::from_reader(text.as_bytes());
    let csv_error = |e: csv::Error| PulseLogError::Csv {
        file: file.to_string(),
        line: e.position().map_or(0, csv::Position::line),
        detail: e.to_string(),
    };
    let headers = r.headers().map_err(csv_error)?.clone();
    // Columns are found by name; a missing optional one reads as an empty field.
    let mut at = [usize::MAX; HEADER.len()];
    for (k, (slot, column)) in at.iter_mut().zip(HEADER).enumerate() {
        match headers.iter().position(|h| h == column) {
            Some(i) => *slot = i,
            None if k >= REQUIRED => {}
            None => {
                return Err(PulseLogError::Column {
                    file: file.to_string(),
                    column,
                    expected: HEADER.join(", "),
                });
            }
        }
    }
    let mut out = Vec::new();
    for record in r.records() {
        let record = record.map_err(csv_error)?;
        let line = record.position().map_or(0, csv::Position::line);
        let field = |k: usize| record.get(at[k]).unwrap_or_default();
        let bad = |k: usize, why: &'static str| PulseLogError::Field {
            file: file.to_string(),
            line,
            column: HEADER[k],
            value: field(k).to_string(),
            why,
        };
        // A number; empty for unknown (NaN).
        let number = |k: usize| -> Result<f64, PulseLogError> {
            let s = field(k).trim();
            if s.is_empty() {
                return Ok(f64::NAN);
            }
            s.parse::<f64>().map_err(|_| bad(k, "is not a number"))
        };
        let time = |k: usize| -> Result<Option<f64>, PulseLogError> {
            let s = field(k).trim();
            if s.is_empty() {
                return Ok(None);
            }
            parse_iso8601(s)
                .map(Some)
                .ok_or_else(|| bad(k, "is not an ISO 8601 time"))
        };
        let t_s = number(0)?;
        if !t_s.is_finite() {
            return Err(bad(0, "is not a time in seconds"));
        }
        let gate_open = match field(10) {
            "open" => true,
            "shut" => false,
            _ => return Err(bad(10, "is neither open nor shut")),
        };
        let image_from_coil = match field(12).trim() {
            "" => None,
            s => {
                let v: Vec<f64> = s
                    .split_whitespace()
                    .map(str::parse::<f64>)
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad(12, "is not 16 numbers"))?;
                if v.len() != 16 || v.iter().any(|x| !x.is_finite()) {
                    return Err(bad(12, "is not 16 numbers"));
                }
                let m = Matrix4::from_fn(|r, c| v[r * 4 + c]);
                Some(
                    mocomp_geom::iso_from_matrix_mm(&m, 1e-4)
                        .map_err(|_| bad(12, "is not a rigid transform in mm"))?,
                )
            }
        };
        let output = number(7)?;
        out.push(Pulse {
            t_s,
            utc_unix_s: time(1)?,
            stimulator_unix_s: time(2)?,
            target: field(3).to_string(),
            position_error_m: number(4)? / 1e3,
            angle_error_rad: number(5)?.to_radians(),
            scalp_distance_m: number(6)? / 1e3,
            output_pct: output.is_finite().then_some(output),
            head_speed: (number(8)? / 1e3, number(9)?.to_radians()),
            gate_open,
            why_shut: field(11).to_string(),
            image_from_coil,
            dose_v_per_m: number(13)?,
            dose_pct: number(14)?,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::gate::Shut;
    use mocomp_geom::nalgebra::Vector3;

    fn at(gate: GateState, coil: Option<Isometry3<f64>>) -> PulseAt {
        PulseAt {
            t_s: 12.5,
            target: 0,
            position_error_m: 0.0012,
            angle_error_rad: 0.5f64.to_radians(),
            head_speed: (0.02, 0.1),
            gate,
            coil,
            stimulator_unix_s: None,
            output_pct: None,
            dose: (142.123_4, 98.765),
        }
    }

    fn recorder() -> Recorder {
        Recorder {
            utc_minus_loop_s: Some(1_796_000_000.25),
            // The image 10 mm along the head marker's x and turned a quarter about z.
            head_from_image: Isometry3::new(
                Vector3::new(0.01, 0.0, 0.0),
                Vector3::z() * std::f64::consts::FRAC_PI_2,
            ),
            head: HeadModel::adult(),
            output_pct: Some(55.0),
        }
    }

    #[test]
    fn a_row_has_the_utc_time_the_image_pose_the_scalp_distance_and_the_output() {
        // The coil 5 mm above the adult ellipsoid's top (110 mm), facing down into the head.
        let coil = Isometry3::new(
            Vector3::new(0.0, 0.0, 0.115),
            Vector3::x() * std::f64::consts::PI,
        );
        let row = recorder().row(&at(GateState::Open, Some(coil)), "C3");
        assert_eq!(row.utc_unix_s, Some(1_796_000_012.75));
        assert!((row.scalp_distance_m - 0.005).abs() < 1e-9, "{row:?}");
        assert_eq!(row.output_pct, Some(55.0));
        // In the image: the head marker's (0, 0, 115 mm) is the image's (0, 10 mm, 115 mm)
        // (the image's x along the marker's y, its origin 10 mm along the marker's x).
        let m = matsimnibs(&row.image_from_coil.unwrap());
        assert!(
            (m[3] - 0.0).abs() < 1e-9 && (m[7] - 10.0).abs() < 1e-9,
            "{m:?}"
        );
        assert!((m[11] - 115.0).abs() < 1e-9 && m[15] == 1.0, "{m:?}");
        // The coil's z (its third column) points down in any frame turned about z.
        assert!((m[10] + 1.0).abs() < 1e-12, "{m:?}");
        // What the stimulator said wins over the configured output; without a head, no pose.
        let mut said = at(GateState::Shut(Shut::NoHead), None);
        said.output_pct = Some(70.0);
        said.stimulator_unix_s = Some(1_796_000_012.7);
        let row = recorder().row(&said, "C3");
        assert_eq!(row.output_pct, Some(70.0));
        assert_eq!(row.image_from_coil, None);
        assert!(row.scalp_distance_m.is_nan());
        assert!(!row.gate_open);
        assert_eq!(row.why_shut, "no head estimate");
    }

    #[test]
    fn iso8601_is_utc_to_the_microsecond_and_reads_back() {
        assert_eq!(iso8601(0.0), "1970-01-01T00:00:00Z");
        assert_eq!(iso8601(1_796_000_012.75), "2026-11-30T00:53:32.75Z");
        let t = 1_796_000_012.123_456;
        assert!((parse_iso8601(&iso8601(t)).unwrap() - t).abs() < 1e-6);
        assert_eq!(iso8601(f64::NAN), "");
        assert_eq!(parse_iso8601("2026-13-01T00:00:00Z"), None);
    }

    #[test]
    fn every_pulse_is_a_row_in_units_that_reads_back_with_a_shut_gate_marked_and_why() {
        let coil = Isometry3::new(Vector3::new(0.01, -0.02, 0.1), Vector3::new(0.3, 2.9, 0.1));
        let mut log = PulseLog::new(Vec::new()).unwrap();
        let r = recorder();
        let first = r.row(&at(GateState::Open, Some(coil)), "hotspot, APB");
        let mut second = at(GateState::Shut(Shut::PositionError(0.004)), None);
        second.t_s = 13.0;
        second.position_error_m = f64::NAN;
        let second = Recorder {
            utc_minus_loop_s: None,
            output_pct: None,
            ..r
        }
        .row(&second, "r0c1");
        log.write(&first).unwrap();
        log.write(&second).unwrap();
        let text = String::from_utf8(log.into_inner().unwrap()).unwrap();
        let mut csv = csv::Reader::from_reader(text.as_bytes());
        assert_eq!(csv.headers().unwrap().iter().collect::<Vec<_>>(), HEADER);
        let rows: Vec<csv::StringRecord> = csv.records().map(Result::unwrap).collect();
        assert_eq!(&rows[0][3], "hotspot, APB");
        assert_eq!(&rows[0][4], "1.200");
        assert_eq!(&rows[0][5], "0.500");
        assert_eq!(&rows[0][7], "55.0");
        assert_eq!(&rows[0][8], "20.00");
        assert_eq!(&rows[0][10], "open");
        assert_eq!(&rows[1][10], "shut");
        assert_eq!(&rows[1][11], "position error 4.00 mm");
        assert_eq!((&rows[1][1], &rows[1][7], &rows[1][12]), ("", "", ""));
        assert_eq!((&rows[0][13], &rows[0][14]), ("142.123", "98.77"));
        // Read back: the same pulses, to the digits written.
        let back = read_log("pulses.csv", &text).unwrap();
        assert_eq!(back.len(), 2);
        let (a, b) = (&back[0], &back[1]);
        assert_eq!(a.target, "hotspot, APB");
        assert!((a.utc_unix_s.unwrap() - first.utc_unix_s.unwrap()).abs() < 1e-6);
        assert!((a.position_error_m - 0.0012).abs() < 1e-9);
        assert!((a.scalp_distance_m - first.scalp_distance_m).abs() < 1e-6);
        let (pa, pf) = (a.image_from_coil.unwrap(), first.image_from_coil.unwrap());
        assert!((pa.translation.vector - pf.translation.vector).norm() < 1e-8);
        assert!(pa.rotation.angle_to(&pf.rotation) < 1e-5);
        assert!(a.gate_open && !b.gate_open);
        assert_eq!(b.why_shut, "position error 4.00 mm");
        assert_eq!(
            (b.utc_unix_s, b.output_pct, b.image_from_coil),
            (None, None, None)
        );
        assert!(b.position_error_m.is_nan());
        assert!((a.dose_v_per_m - 142.123).abs() < 1e-9 && (a.dose_pct - 98.77).abs() < 1e-9);
        // A log from before the dose: its pulses read, without a dose.
        let old: String = text
            .lines()
            .map(|l| {
                let mut r = csv::ReaderBuilder::new()
                    .has_headers(false)
                    .from_reader(l.as_bytes());
                let rec = r.records().next().unwrap().unwrap();
                let mut w = csv::Writer::from_writer(Vec::new());
                w.write_record(rec.iter().take(REQUIRED)).unwrap();
                String::from_utf8(w.into_inner().unwrap()).unwrap()
            })
            .collect();
        let back = read_log("old.csv", &old).unwrap();
        assert_eq!(back.len(), 2);
        assert!(back[0].dose_pct.is_nan() && back[0].dose_v_per_m.is_nan());
        assert_eq!(back[0].target, "hotspot, APB");
        // A dose that is no number is named.
        let bad = text.replacen("98.77", "most", 1);
        let e = read_log("p.csv", &bad).unwrap_err();
        assert!(e.to_string().contains("column dose_pct"), "{e}");
    }

    #[test]
    fn a_log_that_is_not_one_is_named_by_line_and_column() {
        let mut log = PulseLog::new(Vec::new()).unwrap();
        log.write(&recorder().row(&at(GateState::Open, None), "C3"))
            .unwrap();
        let good = String::from_utf8(log.into_inner().unwrap()).unwrap();
        let e = read_log("old.csv", "t_s,target,position_error_mm\n1,C3,0.5\n").unwrap_err();
        assert!(e.to_string().contains("old.csv: no column \"utc\""), "{e}");
        let bad = good.replace(",open,", ",ajar,");
        let e = read_log("p.csv", &bad).unwrap_err();
        assert_eq!(
            e.to_string(),
            "p.csv:2: column gate: \"ajar\" is neither open nor shut"
        );
        let bad = good.replacen("12.5000", "soon", 1);
        let e = read_log("p.csv", &bad).unwrap_err();
        assert!(e.to_string().contains("column t_s"), "{e}");
        let (head, row) = good.split_once('\n').unwrap();
        let mut fields: Vec<String> = csv::ReaderBuilder::new()
            .has_headers(false)
            .from_reader(row.as_bytes())
            .records()
            .next()
            .unwrap()
            .unwrap()
            .iter()
            .map(String::from)
            .collect();
        fields[12] = "1 2 3".into();
        let bad = format!("{head}\n{}\n", fields.join(","));
        let e = read_log("p.csv", &bad).unwrap_err();
        assert!(e.to_string().contains("column matsimnibs"), "{e}");
        let e = read_log("p.csv", &format!("{head}\n1,2\n")).unwrap_err();
        assert!(e.to_string().starts_with("p.csv:2:"), "{e}");
    }
}
