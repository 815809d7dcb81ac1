//! `mocomp calibrate solve`: X and Y from a pairs file, and the report printed (also by
//! `calibrate collect`).

use anyhow::{Context, Result};
use clap::Args;
use mocomp_calib::{Calibration, Method, SolveOptions, parse_pairs_csv, solve};
use mocomp_geom::rows_from_iso;
use mocomp_kin::Model;
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

#[derive(Serialize)]
struct ResidualJson {
    pair: usize,
    line: Option<usize>,
    translation_mm: f64,
    rotation_deg: f64,
    normalized: f64,
    outlier: bool,
    used: bool,
}

#[derive(Serialize)]
struct SolveJson {
    method: &'static str,
    pairs: usize,
    #[serde(rename = "X")]
    x: [[f64; 4]; 4],
    #[serde(rename = "Y")]
    y: [[f64; 4]; 4],
    rms_mm: f64,
    rms_deg: f64,
    max_mm: f64,
    max_deg: f64,
    outliers: Vec<usize>,
    condition: f64,
    axis_spread: f64,
    uncertainty: mocomp_calib::Uncertainty,
    residuals: Vec<ResidualJson>,
}

/// Solve for X and Y from a pairs file (CSV; see README.md for its columns).
#[derive(Debug, Clone, Args)]
pub struct SolveCmd {
    /// The pairs file.
    #[arg(long, value_name = "FILE")]
    pairs: PathBuf,
    /// Solver: li (the paper's linear method), shah, or refined (nonlinear, robust).
    #[arg(long, default_value = "refined", value_parser = ["li", "shah", "refined"])]
    method: String,
    /// Robot model, needed when the file has joint columns q1..q6.
    #[arg(long, value_parser = crate::args::model)]
    robot: Option<Model>,
    /// The robot's own calibrated DH values (TOML), for joint columns.
    #[arg(long, value_name = "FILE", requires = "robot")]
    calibration: Option<PathBuf>,
    /// Expected tracker noise per axis: millimetres, degrees.
    #[arg(long, value_name = "MM,DEG", default_value = "0.1,0.1", value_parser = crate::args::noise_pair)]
    tracker_noise: [f64; 2],
    /// Expected robot noise per axis: millimetres, degrees.
    #[arg(long, value_name = "MM,DEG", default_value = "0.03,0.01", value_parser = crate::args::noise_pair)]
    robot_noise: [f64; 2],
    /// Leave outlier pairs out and solve again (they are reported either way).
    #[arg(long)]
    reject_outliers: bool,
    /// Write X and Y with the residual report to this TOML file.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

impl SolveCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let args = &self;
        let arm = match args.robot {
            Some(model) => Some(crate::args::arm(model, args.calibration.as_deref(), None)?),
            None => None,
        };
        let method: Method = args
            .method
            .parse()
            .map_err(|e| crate::UsageError(format!("--method: {e}")))?;
        let name = args.pairs.display().to_string();
        let text = std::fs::read_to_string(&args.pairs)
            .with_context(|| format!("--pairs {name}: cannot read"))?;
        let pairs = parse_pairs_csv(&text, &name, arm.as_ref())?;
        let options = SolveOptions {
            method,
            noise: super::noise(args.tracker_noise, args.robot_noise),
            reject_outliers: args.reject_outliers,
        };
        let c = solve(&pairs, &options).with_context(|| format!("--pairs {name}"))?;
        let file = c.to_file();
        if let Some(path) = &args.out {
            std::fs::write(path, file.to_toml_string()?)
                .with_context(|| format!("--out {}: cannot write", path.display()))?;
        }
        if args.json {
            let j = SolveJson {
                method: c.method.name(),
                pairs: pairs.len(),
                x: rows_from_iso(&c.flange_from_marker),
                y: rows_from_iso(&c.base_from_tracker),
                rms_mm: c.rms_mm,
                rms_deg: c.rms_deg,
                max_mm: c.max_mm,
                max_deg: c.max_deg,
                outliers: file.outliers.clone(),
                condition: c.condition,
                axis_spread: c.checks.axis_spread,
                uncertainty: c.uncertainty,
                residuals: c
                    .residuals
                    .iter()
                    .map(|r| ResidualJson {
                        pair: r.index + 1,
                        line: r.line,
                        translation_mm: r.translation_mm,
                        rotation_deg: r.rotation_deg,
                        normalized: r.normalized,
                        outlier: r.outlier,
                        used: r.used,
                    })
                    .collect(),
            };
            writeln!(out, "{}", serde_json::to_string(&j)?)?;
            return Ok(());
        }
        print_report(out, &c, pairs.len())?;
        if let Some(path) = &args.out {
            writeln!(out, "wrote {}", path.display())?;
        }
        Ok(())
    }
}

pub(crate) fn print_report(out: &mut dyn Write, c: &Calibration, n: usize) -> Result<()> {
    writeln!(
        out,
        "method {}, {n} pairs ({} nonlinear iterations)",
        c.method, c.iterations
    )?;
    crate::print::transform(
        out,
        "X = flange_from_marker (metres)",
        &c.flange_from_marker,
        true,
    )?;
    crate::print::transform(
        out,
        "Y = base_from_tracker (metres)",
        &c.base_from_tracker,
        true,
    )?;
    writeln!(
        out,
        "residuals over the pairs used: RMS {:.3} mm, {:.3}°; max {:.3} mm, {:.3}°",
        c.rms_mm, c.rms_deg, c.max_mm, c.max_deg
    )?;
    let u = &c.uncertainty;
    writeln!(
        out,
        "uncertainty (1σ): X {:.3}°, {:.3} mm; Y {:.3}°, {:.3} mm",
        u.x_rotation_deg, u.x_translation_mm, u.y_rotation_deg, u.y_translation_mm
    )?;
    writeln!(
        out,
        "pose set: largest rotation {:.1}°, axis spread {:.2} (0 = one axis), condition {:.1}",
        c.checks.max_rotation_deg, c.checks.axis_spread, c.condition
    )?;
    let mut worst: Vec<_> = c.residuals.iter().collect();
    worst.sort_by(|a, b| b.normalized.total_cmp(&a.normalized));
    writeln!(out, "largest residuals:")?;
    for r in worst.iter().take(5) {
        let place = r
            .line
            .map(|l| format!("line {l}"))
            .unwrap_or_else(|| format!("pair {}", r.index + 1));
        writeln!(
            out,
            "  {place:<10} {:>8.3} mm {:>7.3}°  normalised {:>6.2}{}{}",
            r.translation_mm,
            r.rotation_deg,
            r.normalized,
            if r.outlier { "  OUTLIER" } else { "" },
            if r.used { "" } else { " (left out)" }
        )?;
    }
    if !c.checks.suspect.is_empty() {
        let names: Vec<String> = c
            .checks
            .suspect
            .iter()
            .map(|&i| {
                c.residuals[i]
                    .line
                    .map(|l| format!("line {l}"))
                    .unwrap_or_else(|| format!("pair {}", i + 1))
            })
            .collect();
        writeln!(
            out,
            "before solving, these pairs' motion disagreed with most others: {}",
            names.join(", ")
        )?;
    }
    if c.outliers.is_empty() {
        writeln!(out, "outliers: none")?;
    } else {
        writeln!(
            out,
            "outliers: {} pair(s){}",
            c.outliers.len(),
            if c.residuals.iter().any(|r| !r.used) {
                ", left out"
            } else {
                "; use --reject-outliers to leave them out"
            }
        )?;
    }
    Ok(())
}
