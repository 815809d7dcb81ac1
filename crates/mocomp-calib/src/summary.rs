//! A calibration and a calibration plan as they are reported: JSON for tools
//! ([`SolveSummary`], [`PlanReport`]) and the text a person reads (their `Display`).

use crate::Calibration;
use crate::plan::PlannedPose;
use mocomp_geom::text::{row, transform};
use mocomp_geom::{rows_from_iso, ur_pose_from_iso};
use serde::Serialize;
use std::fmt;

/// One pair's residual, as reported (1-based pair number).
#[derive(Debug, Clone, Serialize)]
pub struct ResidualLine {
    /// 1-based pair number.
    pub pair: usize,
    /// 1-based line in the pairs file, when known.
    pub line: Option<usize>,
    /// Translation residual, mm.
    pub translation_mm: f64,
    /// Rotation residual, degrees.
    pub rotation_deg: f64,
    /// Normalised by the noise model.
    pub normalized: f64,
    /// Flagged as an outlier.
    pub outlier: bool,
    /// Used in the solution.
    pub used: bool,
}

/// A calibration as one JSON object: X and Y (row-major 4×4, metres), the residuals and the
/// figures that say how far to trust them.
#[derive(Debug, Clone, Serialize)]
pub struct SolveSummary {
    /// The solver's name.
    pub method: &'static str,
    /// Pairs in the set.
    pub pairs: usize,
    /// `X = flange_from_marker`.
    #[serde(rename = "X")]
    pub x: [[f64; 4]; 4],
    /// `Y = base_from_tracker`.
    #[serde(rename = "Y")]
    pub y: [[f64; 4]; 4],
    /// RMS translation residual over the pairs used, mm.
    pub rms_mm: f64,
    /// RMS rotation residual, degrees.
    pub rms_deg: f64,
    /// Largest translation residual, mm.
    pub max_mm: f64,
    /// Largest rotation residual, degrees.
    pub max_deg: f64,
    /// 1-based numbers of the outlier pairs.
    pub outliers: Vec<usize>,
    /// Condition number of the information matrix.
    pub condition: f64,
    /// Spread of the rotation axes (0 = one axis).
    pub axis_spread: f64,
    /// 1σ uncertainty of X and Y.
    pub uncertainty: crate::Uncertainty,
    /// Every pair's residual.
    pub residuals: Vec<ResidualLine>,
}

impl Calibration {
    /// The calibration as its JSON summary.
    pub fn summary(&self) -> SolveSummary {
        SolveSummary {
            method: self.method.name(),
            pairs: self.residuals.len(),
            x: rows_from_iso(&self.flange_from_marker),
            y: rows_from_iso(&self.base_from_tracker),
            rms_mm: self.rms_mm,
            rms_deg: self.rms_deg,
            max_mm: self.max_mm,
            max_deg: self.max_deg,
            outliers: self.to_file().outliers,
            condition: self.condition,
            axis_spread: self.checks.axis_spread,
            uncertainty: self.uncertainty,
            residuals: self
                .residuals
                .iter()
                .map(|r| ResidualLine {
                    pair: r.index + 1,
                    line: r.line,
                    translation_mm: r.translation_mm,
                    rotation_deg: r.rotation_deg,
                    normalized: r.normalized,
                    outlier: r.outlier,
                    used: r.used,
                })
                .collect(),
        }
    }

    /// Where pair `i` is, for a person: its line in the file, else its number.
    fn place(&self, i: usize) -> String {
        self.residuals[i]
            .line
            .map(|l| format!("line {l}"))
            .unwrap_or_else(|| format!("pair {}", i + 1))
    }
}

/// The report: X and Y, the residuals, the uncertainty, the pose set's quality, the five
/// largest residuals, the suspect pairs and the outliers.
impl fmt::Display for Calibration {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.residuals.len();
        writeln!(
            f,
            "method {}, {n} pairs ({} nonlinear iterations)",
            self.method, self.iterations
        )?;
        let x = "X = flange_from_marker (metres)";
        write!(f, "{}", transform(x, &self.flange_from_marker, true))?;
        let y = "Y = base_from_tracker (metres)";
        write!(f, "{}", transform(y, &self.base_from_tracker, true))?;
        writeln!(
            f,
            "residuals over the pairs used: RMS {:.3} mm, {:.3}°; max {:.3} mm, {:.3}°",
            self.rms_mm, self.rms_deg, self.max_mm, self.max_deg
        )?;
        let u = &self.uncertainty;
        writeln!(
            f,
            "uncertainty (1σ): X {:.3}°, {:.3} mm; Y {:.3}°, {:.3} mm",
            u.x_rotation_deg, u.x_translation_mm, u.y_rotation_deg, u.y_translation_mm
        )?;
        writeln!(
            f,
            "pose set: largest rotation {:.1}°, axis spread {:.2} (0 = one axis), condition {:.1}",
            self.checks.max_rotation_deg, self.checks.axis_spread, self.condition
        )?;
        let mut worst: Vec<_> = self.residuals.iter().collect();
        worst.sort_by(|a, b| b.normalized.total_cmp(&a.normalized));
        writeln!(f, "largest residuals:")?;
        for r in worst.iter().take(5) {
            writeln!(
                f,
                "  {:<10} {:>8.3} mm {:>7.3}°  normalised {:>6.2}{}{}",
                self.place(r.index),
                r.translation_mm,
                r.rotation_deg,
                r.normalized,
                if r.outlier { "  OUTLIER" } else { "" },
                if r.used { "" } else { " (left out)" }
            )?;
        }
        if !self.checks.suspect.is_empty() {
            let names: Vec<String> = self.checks.suspect.iter().map(|&i| self.place(i)).collect();
            writeln!(
                f,
                "before solving, these pairs' motion disagreed with most others: {}",
                names.join(", ")
            )?;
        }
        if self.outliers.is_empty() {
            return writeln!(f, "outliers: none");
        }
        writeln!(
            f,
            "outliers: {} pair(s){}",
            self.outliers.len(),
            if self.residuals.iter().any(|r| !r.used) {
                ", left out"
            } else {
                "; use --reject-outliers to leave them out"
            }
        )
    }
}

/// One planned pose, as reported.
#[derive(Debug, Clone, Serialize)]
pub struct PlannedLine {
    /// Joints, radians.
    pub joints: [f64; 6],
    /// The flange as a UR pose vector.
    pub pose: [f64; 6],
    /// Rotation from the centre, degrees.
    pub rotation_deg: f64,
}

/// A calibration plan: where it starts, its poses and the time to visit them.
#[derive(Debug, Clone, Serialize)]
pub struct PlanReport {
    /// The joints the tour starts from.
    pub current: [f64; 6],
    /// The poses in visiting order.
    pub poses: Vec<PlannedLine>,
    /// The tour's time at full joint speed, seconds.
    pub tour_time_s: f64,
    #[serde(skip)]
    model: String,
    #[serde(skip)]
    tracker_checked: bool,
}

impl PlanReport {
    /// The plan of `poses` on `model` from `current`; `tracker_checked` says whether the
    /// tracker's view was checked.
    pub fn new(
        model: impl fmt::Display,
        current: [f64; 6],
        poses: &[PlannedPose],
        tour_time_s: f64,
        tracker_checked: bool,
    ) -> Self {
        Self {
            current,
            poses: poses
                .iter()
                .map(|p| PlannedLine {
                    joints: p.joints,
                    pose: ur_pose_from_iso(&p.base_from_flange),
                    rotation_deg: p.rotation_rad.to_degrees(),
                })
                .collect(),
            tour_time_s,
            model: model.to_string(),
            tracker_checked,
        }
    }
}

impl fmt::Display for PlanReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} calibration poses for {} from [{}] (radians; flange pose in m, rotation vector)",
            self.poses.len(),
            self.model,
            row(&self.current)
        )?;
        for (i, p) in self.poses.iter().enumerate() {
            writeln!(
                f,
                "{:>3}  q [{}]  pose [{}]  {:>5.1}°",
                i + 1,
                row(&p.joints),
                row(&p.pose),
                p.rotation_deg
            )?;
        }
        writeln!(
            f,
            "moves at full joint speed: {:.1} s in all{}",
            self.tour_time_s,
            if self.tracker_checked {
                "; every marker pose inside the tracker's view"
            } else {
                "; no --tracker given, visibility not checked"
            }
        )
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use crate::synth::{SynthOptions, synthesize};
    use crate::{Method, SolveOptions, solve};

    #[test]
    fn the_report_names_the_method_the_pairs_and_the_worst_five() {
        let o = SynthOptions {
            count: 12,
            ..Default::default()
        };
        let pairs = synthesize(&o).unwrap();
        let options = SolveOptions {
            method: Method::Li,
            noise: o.noise.unwrap_or_default(),
            reject_outliers: false,
        };
        let c = solve(&pairs, &options).unwrap();
        let text = c.to_string();
        assert!(text.starts_with("method li, 12 pairs"), "{text}");
        let listed = text.lines().filter(|l| l.contains("normalised")).count();
        assert_eq!(listed, 5);
        let s = c.summary();
        assert_eq!(
            (s.pairs, s.residuals.len(), s.residuals[0].pair),
            (12, 12, 1)
        );
    }
}
