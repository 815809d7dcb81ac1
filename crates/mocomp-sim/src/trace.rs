//! Recorded head motion, replayed: a tracker's head poses from a CSV file with the header
//! `t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz` (columns in any order, `#` comments allowed), turned into the
//! head's displacement from its first sample, in the head's own frame, at any time.
//!
//! Sample times may be irregular and sparse: position is interpolated by a cubic Hermite spline
//! (tangents from the neighbouring samples, as Catmull–Rom on an irregular grid), rotation by
//! slerp between neighbours. Before the first sample the head is at its first pose; after the
//! last it stays at the last. A trace whose position columns are all zero moves only in
//! rotation. No I/O here but [`MotionTrace::load`], which reads the file and parses it.

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
    /// `first_from_head` rotation per sample.
    q: Vec<UnitQuaternion<f64>>,
}

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
        let (mut t, mut poses) = (Vec::new(), Vec::new());
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
        Ok(Self {
            t: t.iter().map(|x| x - t0).collect(),
            p: rel.iter().map(|r| r.translation.vector).collect(),
            q: rel.iter().map(|r| r.rotation).collect(),
        })
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
        let (t0, t1) = (self.t[i], self.t[i + 1]);
        let h = t1 - t0;
        let s = (t - t0) / h;
        let (m0, m1) = (self.tangent(i), self.tangent(i + 1));
        let (s2, s3) = (s * s, s * s * s);
        let p = self.p[i] * (2.0 * s3 - 3.0 * s2 + 1.0)
            + m0 * (h * (s3 - 2.0 * s2 + s))
            + self.p[i + 1] * (-2.0 * s3 + 3.0 * s2)
            + m1 * (h * (s3 - s2));
        Isometry3::from_parts(
            Translation3::from(p),
            mocomp_geom::slerp(&self.q[i], &self.q[i + 1], s),
        )
    }

    fn pose(&self, i: usize) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.p[i]), self.q[i])
    }

    /// The velocity at sample `i` (m/s): the finite difference across its neighbours on the
    /// irregular grid, one-sided at the ends (a trace that starts or ends mid-motion keeps its
    /// speed there instead of overshooting to catch up).
    fn tangent(&self, i: usize) -> Vector3<f64> {
        let n = self.t.len();
        if n < 2 {
            return Vector3::zeros();
        }
        let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
        (self.p[b] - self.p[a]) / (self.t[b] - self.t[a])
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
