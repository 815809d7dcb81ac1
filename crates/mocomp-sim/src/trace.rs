//! Recorded head motion, replayed: a tracker's head poses from a CSV file with the header
//! `t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz` (columns in any order, `#` comments allowed), turned into the
//! head's displacement from its first sample, in the head's own frame, at any time.
//!
//! Sample times may be irregular and sparse (a tracker logging 10–90 ms apart while the head
//! moves and seconds apart while it is still). The replay never invents motion the samples do not
//! show:
//! - **Position.** A monotone piecewise-cubic Hermite interpolant (PCHIP: Fritsch–Carlson
//!   tangents, the weighted harmonic mean of the neighbouring slopes on the irregular grid, zero
//!   at a local extremum). Between two samples each coordinate stays between their values: no
//!   overshoot, and a head still for seconds stays still until the sample where it moves. The
//!   curve passes through every sample with a continuous velocity.
//! - **Rotation.** The same interpolant on the rotation vector of each sample from the first,
//!   which is smooth (continuous angular velocity, unlike slerp between neighbours) and equally
//!   free of overshoot per component. A head never turns half a turn from where it started; a
//!   trace that does (over 170°) is refused naming its line.
//!
//! Before the first sample the head is at its first pose; after the last it stays at the last. A
//! trace whose position columns are all zero moves only in rotation. No I/O here but
//! [`MotionTrace::load`], which reads the file and parses it.

use mocomp_geom::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use std::path::Path;

/// The columns a trace must have.
pub const COLUMNS: [&str; 8] = ["t_s", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"];

/// A trace could not be read; the message names the file, line and column.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// The file could not be read.
    #[error("{file}: cannot read: {source}")]
    Read {
        /// The file.
        file: String,
        /// The cause.
        source: std::io::Error,
    },
    /// The content is malformed.
    #[error("{file}: line {line}, column {column}: {problem}")]
    Malformed {
        /// The file.
        file: String,
        /// 1-based line.
        line: u64,
        /// The column's name (or its 1-based number when the header is at fault).
        column: String,
        /// What is wrong.
        problem: String,
    },
}

/// A recorded head motion relative to its first sample.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionTrace {
    /// Sample times from the first sample, s (strictly increasing, starting at 0).
    t: Vec<f64>,
    /// `first_from_head` translation per sample, m.
    p: Vec<Vector3<f64>>,
    /// `first_from_head` rotation per sample, as a rotation vector (rad).
    r: Vec<Vector3<f64>>,
    /// The position's tangent at each sample, m/s.
    dp: Vec<Vector3<f64>>,
    /// The rotation vector's tangent at each sample, rad/s.
    dr: Vec<Vector3<f64>>,
}

/// The largest rotation from the first sample a trace may hold, rad: the rotation vector is a
/// smooth chart of the rotations only away from a half turn.
pub const MAX_TURN_RAD: f64 = 170.0 * std::f64::consts::PI / 180.0;

impl MotionTrace {
    /// Reads and parses `path`.
    pub fn load(path: &Path) -> Result<Self, TraceError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| TraceError::Read {
            file: file.clone(),
            source,
        })?;
        Self::parse(&file, &text)
    }

    /// Parses a trace; `file` names it in errors.
    pub fn parse(file: &str, text: &str) -> Result<Self, TraceError> {
        let bad = |line: u64, column: &str, problem: String| TraceError::Malformed {
            file: file.to_string(),
            line,
            column: column.to_string(),
            problem,
        };
        let mut reader = csv::ReaderBuilder::new()
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_reader(text.as_bytes());
        let header = reader
            .headers()
            .map_err(|e| bad(1, "1", format!("unreadable header: {e}")))?
            .clone();
        let mut at = [usize::MAX; 8];
        for (i, name) in header.iter().enumerate() {
            match COLUMNS.iter().position(|c| *c == name) {
                Some(k) if at[k] == usize::MAX => at[k] = i,
                Some(_) => return Err(bad(1, name, "the column appears twice".into())),
                None => {
                    return Err(bad(
                        1,
                        &(i + 1).to_string(),
                        format!(
                            "unknown column {name:?} (the columns: {})",
                            COLUMNS.join(",")
                        ),
                    ));
                }
            }
        }
        if let Some(k) = at.iter().position(|i| *i == usize::MAX) {
            return Err(bad(1, COLUMNS[k], "missing column".into()));
        }
        let (mut t, mut poses, mut lines) = (Vec::new(), Vec::new(), Vec::new());
        for record in reader.records() {
            let record = record.map_err(|e| {
                let line = e.position().map_or(0, csv::Position::line);
                bad(line, "-", e.to_string())
            })?;
            let line = record.position().map_or(0, csv::Position::line);
            let mut v = [0.0; 8];
            for (k, name) in COLUMNS.iter().enumerate() {
                let cell = record.get(at[k]).unwrap_or("");
                v[k] = cell
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(line, name, format!("{cell:?} is not a finite number")))?;
            }
            if let Some(&last) = t.last()
                && v[0] <= last
            {
                return Err(bad(
                    line,
                    "t_s",
                    format!("{} s is not after the previous sample's {last} s", v[0]),
                ));
            }
            let raw = Quaternion::new(v[4], v[5], v[6], v[7]);
            let n = raw.norm();
            if (n - 1.0).abs() > 1e-3 {
                return Err(bad(
                    line,
                    "qw",
                    format!("the quaternion's norm is {n}, not 1"),
                ));
            }
            t.push(v[0]);
            lines.push(line);
            poses.push(Isometry3::from_parts(
                Translation3::new(v[1] * 1e-3, v[2] * 1e-3, v[3] * 1e-3),
                UnitQuaternion::from_quaternion(raw),
            ));
        }
        let Some(first) = poses.first().copied() else {
            return Err(bad(2, "t_s", "no samples".into()));
        };
        let t0 = t[0];
        let first_inv = first.inverse();
        let rel: Vec<Isometry3<f64>> = poses.iter().map(|p| first_inv * p).collect();
        if let Some(k) = rel.iter().position(|r| r.rotation.angle() > MAX_TURN_RAD) {
            return Err(bad(
                lines[k],
                "qw",
                format!(
                    "the head has turned {:.0}° from the first sample: more than {:.0}° is not a head",
                    rel[k].rotation.angle().to_degrees(),
                    MAX_TURN_RAD.to_degrees()
                ),
            ));
        }
        let t: Vec<f64> = t.iter().map(|x| x - t0).collect();
        let p: Vec<Vector3<f64>> = rel.iter().map(|r| r.translation.vector).collect();
        let r: Vec<Vector3<f64>> = rel.iter().map(|r| r.rotation.scaled_axis()).collect();
        let (dp, dr) = (pchip_tangents(&t, &p), pchip_tangents(&t, &r));
        Ok(Self { t, p, r, dp, dr })
    }

    /// Samples in the trace.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// Whether it has no samples (never, once parsed).
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The time from the first sample to the last, s.
    pub fn duration_s(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0)
    }

    /// The head's displacement from its first sample at `t` seconds after it.
    pub fn rest_from_head(&self, t: f64) -> Isometry3<f64> {
        let n = self.t.len();
        if n == 0 {
            return Isometry3::identity();
        }
        if t <= 0.0 || n == 1 {
            return self.pose(if t <= 0.0 { 0 } else { n - 1 });
        }
        if t >= self.t[n - 1] {
            return self.pose(n - 1);
        }
        // The interval [t_i, t_{i+1}] holding t.
        let i = self.t.partition_point(|x| *x <= t) - 1;
        let h = self.t[i + 1] - self.t[i];
        let s = (t - self.t[i]) / h;
        let p = hermite(&self.p, &self.dp, i, h, s);
        let r = hermite(&self.r, &self.dr, i, h, s);
        Isometry3::from_parts(Translation3::from(p), UnitQuaternion::from_scaled_axis(r))
    }

    fn pose(&self, i: usize) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(self.p[i]),
            UnitQuaternion::from_scaled_axis(self.r[i]),
        )
    }
}

/// The cubic Hermite curve through `y[i]` and `y[i + 1]` with tangents `m` there, at `s` (0…1)
/// of the interval of length `h`.
fn hermite(y: &[Vector3<f64>], m: &[Vector3<f64>], i: usize, h: f64, s: f64) -> Vector3<f64> {
    let (s2, s3) = (s * s, s * s * s);
    y[i] * (2.0 * s3 - 3.0 * s2 + 1.0)
        + m[i] * (h * (s3 - 2.0 * s2 + s))
        + y[i + 1] * (-2.0 * s3 + 3.0 * s2)
        + m[i + 1] * (h * (s3 - s2))
}

/// PCHIP's tangents at each sample, per component (Fritsch and Carlson 1980; the weights of
/// Fritsch and Butland 1984 for an irregular grid; the three-point ends, limited so they keep
/// the shape): zero where the slopes either side differ in sign or one is flat.
fn pchip_tangents(t: &[f64], y: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    let n = t.len();
    let mut m = vec![Vector3::zeros(); n];
    if n < 2 {
        return m;
    }
    let h: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let d: Vec<Vector3<f64>> = (0..n - 1).map(|k| (y[k + 1] - y[k]) / h[k]).collect();
    if n == 2 {
        return vec![d[0], d[0]];
    }
    for c in 0..3 {
        for k in 1..n - 1 {
            let (a, b) = (d[k - 1][c], d[k][c]);
            m[k][c] = if a * b <= 0.0 {
                0.0
            } else {
                let (w1, w2) = (2.0 * h[k] + h[k - 1], h[k] + 2.0 * h[k - 1]);
                (w1 + w2) / (w1 / a + w2 / b)
            };
        }
        m[0][c] = end_tangent(h[0], h[1], d[0][c], d[1][c]);
        m[n - 1][c] = end_tangent(h[n - 2], h[n - 3], d[n - 2][c], d[n - 3][c]);
    }
    m
}

/// The end tangent from the end interval (`h0`, slope `d0`) and its neighbour (`h1`, `d1`).
fn end_tangent(h0: f64, h1: f64, d0: f64, d1: f64) -> f64 {
    let m = ((2.0 * h0 + h1) * d0 - h0 * d1) / (h0 + h1);
    if m * d0 <= 0.0 {
        0.0
    } else if d0 * d1 < 0.0 && m.abs() > 3.0 * d0.abs() {
        3.0 * d0
    } else {
        m
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    const HEADER: &str = "t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz\n";

    fn err(text: &str) -> String {
        MotionTrace::parse("trace.csv", text)
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn the_motion_is_relative_to_the_first_sample_in_the_heads_own_frame() {
        // The head starts turned 90° about z, 1 m out; it then moves 10 mm along the tracker's x,
        // which is along the head's own −y.
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let text = format!("{HEADER}0.0,1000,0,0,{c},0,0,{c}\n1.0,1010,0,0,{c},0,0,{c}\n");
        let tr = MotionTrace::parse("t", &text).unwrap();
        let end = tr.rest_from_head(5.0);
        assert!((end.translation.vector - Vector3::new(0.0, -0.01, 0.0)).norm() < 1e-12);
        assert!(end.rotation.angle() < 1e-12);
        let before = tr.rest_from_head(-1.0);
        assert!(before.translation.vector.norm() < 1e-12 && before.rotation.angle() < 1e-9);
        assert_eq!(tr.duration_s(), 1.0);
    }

    #[test]
    fn irregular_samples_are_interpolated_through_every_sample_and_smoothly() {
        // Samples of x = 10 sin(t) mm at irregular times, about z turning at 0.3 rad/s.
        let times: [f64; 9] = [0.0, 0.05, 0.3, 0.32, 0.7, 1.1, 1.13, 1.6, 2.0];
        let mut text = HEADER.to_string();
        for &t in &times {
            let a = 0.15 * t;
            text += &format!(
                "{t},{},0,0,{},0,0,{}\n",
                10.0 * (3.0 * t).sin(),
                a.cos(),
                a.sin()
            );
        }
        let tr = MotionTrace::parse("t", &text).unwrap();
        for &t in &times {
            let p = tr.rest_from_head(t);
            assert!(
                (p.translation.x - 0.01 * (3.0 * t).sin()).abs() < 1e-12,
                "{t}"
            );
            assert!((p.rotation.angle() - 0.3 * t).abs() < 1e-9, "{t}");
        }
        // Between samples: close to the truth, continuous (no jumps at the knots), and no faster
        // than the motion itself (30 mm/s) by more than the sampling explains, from the start:
        // the trace begins mid-motion.
        let mut peak = 0.0f64;
        let mut k = 0.0;
        while k <= 2.0 {
            let (a, b) = (tr.rest_from_head(k), tr.rest_from_head(k + 1e-4));
            peak = peak.max((b.translation.vector - a.translation.vector).norm() / 1e-4);
            k += 0.001;
        }
        assert!(peak < 0.036, "{peak}");
        let mut prev = tr.rest_from_head(0.0);
        let mut k = 0.0;
        while k <= 2.0 {
            let p = tr.rest_from_head(k);
            assert!(
                (p.translation.x - 0.01 * (3.0 * k).sin()).abs() < 2e-3,
                "{k}"
            );
            assert!(
                (p.translation.vector - prev.translation.vector).norm() < 1e-4,
                "{k}"
            );
            prev = p;
            k += 0.001;
        }
    }

    /// A seated head's log: still for seconds between bursts that start at 45 mm/s and 30°/s
    /// within a sample, sampled 10–90 ms apart while moving.
    fn bursts(seed: u64) -> (Vec<f64>, Vec<[f64; 4]>) {
        let mut state = seed;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (mut t, mut v) = (vec![0.0], vec![[0.0; 4]]);
        let mut now = [0.0f64; 4];
        for _ in 0..6 {
            // Still, one sample seconds later.
            let gap = 1.0 + 4.6 * next();
            t.push(t[t.len() - 1] + gap);
            v.push(now);
            // A burst: x, y, z (mm) at up to 45 mm/s, the angle (rad) at up to 30°/s.
            let dir: [f64; 4] = std::array::from_fn(|_| next() * 2.0 - 1.0);
            for _ in 0..(5 + (next() * 10.0) as usize) {
                let dt = 0.01 + 0.08 * next();
                for k in 0..3 {
                    now[k] += dir[k] * 45.0 * dt;
                }
                now[3] += dir[3] * 30f64.to_radians() * dt;
                t.push(t[t.len() - 1] + dt);
                v.push(now);
            }
        }
        (t, v)
    }

    fn csv(t: &[f64], v: &[[f64; 4]]) -> String {
        let mut text = HEADER.to_string();
        for (t, v) in t.iter().zip(v) {
            let a = v[3] / 2.0;
            text += &format!(
                "{t},{},{},{},{},0,0,{}\n",
                v[0],
                v[1],
                v[2],
                a.cos(),
                a.sin()
            );
        }
        text
    }

    #[test]
    fn a_sparse_irregular_log_is_replayed_without_overshoot_or_motion_before_it_starts() {
        for seed in 1..=20 {
            let (t, v) = bursts(seed);
            let tr = MotionTrace::parse("t", &csv(&t, &v)).unwrap();
            for i in 0..t.len() - 1 {
                // Through every sample.
                let at = tr.rest_from_head(t[i]);
                assert!(
                    (at.translation.x * 1e3 - v[i][0]).abs() < 1e-9,
                    "{seed} {i}"
                );
                // Between two samples every coordinate stays between their values.
                for k in 1..20 {
                    let tk = t[i] + (t[i + 1] - t[i]) * k as f64 / 20.0;
                    let p = tr.rest_from_head(tk);
                    let got = [
                        p.translation.x * 1e3,
                        p.translation.y * 1e3,
                        p.translation.z * 1e3,
                        p.rotation.scaled_axis().z,
                    ];
                    for c in 0..4 {
                        let (lo, hi) = (v[i][c].min(v[i + 1][c]), v[i][c].max(v[i + 1][c]));
                        assert!(
                            got[c] >= lo - 1e-9 && got[c] <= hi + 1e-9,
                            "seed {seed}, interval {i}, component {c}: {} outside [{lo}, {hi}]",
                            got[c]
                        );
                    }
                }
            }
            // The velocity is continuous at every sample.
            for (i, &ti) in t.iter().enumerate().take(t.len() - 1).skip(1) {
                let e = 1e-7;
                let speed = |a: f64, b: f64| {
                    (tr.rest_from_head(b).translation.vector
                        - tr.rest_from_head(a).translation.vector)
                        / (b - a)
                };
                let (left, right) = (speed(ti - 2.0 * e, ti - e), speed(ti + e, ti + 2.0 * e));
                assert!(
                    (left - right).norm() < 1e-4,
                    "seed {seed}, sample {i}: {left} against {right}"
                );
            }
        }
    }

    #[test]
    fn a_trace_that_turns_half_a_turn_is_refused_naming_its_line() {
        let e = err(&format!(
            "{HEADER}0,0,0,0,1,0,0,0\n0.1,0,0,0,0.0436,0,0,0.999\n"
        ));
        assert!(e.contains("line 3") && e.contains("turned"), "{e}");
    }

    #[test]
    fn an_orientation_only_trace_turns_without_moving() {
        let text = format!("{HEADER}0,0,0,0,1,0,0,0\n0.5,0,0,0,0.9238795,0,0.3826834,0\n");
        let p = MotionTrace::parse("t", &text).unwrap().rest_from_head(0.25);
        assert_eq!(p.translation.vector, Vector3::zeros());
        assert!((p.rotation.angle() - std::f64::consts::FRAC_PI_8).abs() < 1e-6);
    }

    #[test]
    fn columns_in_any_order_and_comments_are_accepted() {
        let text = "# recorded\nqw,qx,qy,qz,t_s,x_mm,y_mm,z_mm\n1,0,0,0,0,0,0,0\n1,0,0,0,1,5,0,0\n";
        let tr = MotionTrace::parse("t", text).unwrap();
        assert!((tr.rest_from_head(2.0).translation.x - 0.005).abs() < 1e-12);
    }

    #[test]
    fn malformed_files_are_named_with_line_and_column() {
        let e = err("t_s,x_mm,y_mm,z_mm,qw,qx,qy\n");
        assert!(
            e.contains("line 1") && e.contains("qz") && e.contains("missing"),
            "{e}"
        );
        let e = err("t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz,speed\n");
        assert!(e.contains("column 9") && e.contains("speed"), "{e}");
        let e = err(&format!("{HEADER}0,0,0,0,1,0,0,0\n0.1,0,abc,0,1,0,0,0\n"));
        assert!(
            e.contains("trace.csv: line 3, column y_mm") && e.contains("abc"),
            "{e}"
        );
        let e = err(&format!("{HEADER}0,0,0,0,1,0,0,0\n0,0,0,0,1,0,0,0\n"));
        assert!(
            e.contains("line 3, column t_s") && e.contains("not after"),
            "{e}"
        );
        let e = err(&format!("{HEADER}0,0,0,0,2,0,0,0\n"));
        assert!(e.contains("line 2, column qw") && e.contains("norm"), "{e}");
        let e = err(&format!("{HEADER}0,0,0,0,1,0,0\n"));
        assert!(e.contains("line 2"), "{e}");
        let e = err(HEADER);
        assert!(e.contains("no samples"), "{e}");
        let e = err(&format!("{HEADER}0,NaN,0,0,1,0,0,0\n"));
        assert!(e.contains("column x_mm") && e.contains("finite"), "{e}");
        let e = MotionTrace::load(Path::new("/nonexistent/trace.csv"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("/nonexistent/trace.csv") && e.contains("cannot read"),
            "{e}"
        );
    }
}
