//! `mocomp calibrate solve`: X and Y from a pairs file, and the report printed.

use anyhow::{Context, Result};
use clap::Args;
use mocomp_calib::{Method, SolveOptions, parse_pairs_csv, solve};
use mocomp_kin::Model;
use std::io::Write;
use std::path::PathBuf;

/// Solve for X and Y from a pairs file (CSV; its columns are on the book's commands page, book/src/reference/commands.md).
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
            writeln!(out, "{}", serde_json::to_string(&c.summary())?)?;
            return Ok(());
        }
        write!(out, "{c}")?;
        if let Some(path) = &args.out {
            writeln!(out, "wrote {}", path.display())?;
        }
        Ok(())
    }
}
