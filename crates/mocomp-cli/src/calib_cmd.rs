//! `mocomp calibrate solve|plan|synth`: printing and writing what `mocomp-calib` computes.

use anyhow::{Context, Result};
use mocomp_calib::plan::{PlanOptions, TrackerView, plan, tour_time};
use mocomp_calib::synth::{SynthOptions, synthesize};
use mocomp_calib::{
    Calibration, Method, NoiseModel, PairsFormat, SolveOptions, parse_pairs_csv, solve,
    write_pairs_csv,
};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{rows_from_iso, ur_pose_from_iso};
use mocomp_kin::{Arm, Selection};
use serde::Serialize;
use std::io::Write;
use std::path::Path;

/// Options of `calibrate solve`.
#[derive(Debug)]
pub struct SolveArgs<'a> {
    /// The pairs file.
    pub pairs: &'a Path,
    /// For joint columns.
    pub arm: Option<Arm>,
    /// Solver.
    pub method: Method,
    /// Noise model.
    pub noise: NoiseModel,
    /// Leave outliers out.
    pub reject_outliers: bool,
    /// Result file to write.
    pub out_file: Option<&'a Path>,
    /// Print JSON.
    pub json: bool,
}

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

/// `calibrate solve`.
pub fn solve_cmd(out: &mut dyn Write, args: &SolveArgs<'_>) -> Result<()> {
    let name = args.pairs.display().to_string();
    let text = std::fs::read_to_string(args.pairs)
        .with_context(|| format!("--pairs {name}: cannot read"))?;
    let pairs = parse_pairs_csv(&text, &name, args.arm.as_ref())?;
    let options = SolveOptions {
        method: args.method,
        noise: args.noise,
        reject_outliers: args.reject_outliers,
    };
    let c = solve(&pairs, &options).with_context(|| format!("--pairs {name}"))?;
    let file = c.to_file();
    if let Some(path) = args.out_file {
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
    if let Some(path) = args.out_file {
        writeln!(out, "wrote {}", path.display())?;
    }
    Ok(())
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

/// Options of `calibrate plan`.
#[derive(Debug)]
pub struct PlanArgs {
    /// The robot.
    pub arm: Arm,
    /// Centre flange pose.
    pub center: Isometry3<f64>,
    /// Number of poses.
    pub count: usize,
    /// Current joints (None: the IK solution of the centre nearest the zero configuration).
    pub current: Option<[f64; 6]>,
    /// Rough flange_from_marker.
    pub marker: Option<Isometry3<f64>>,
    /// Rough base_from_tracker.
    pub tracker: Option<Isometry3<f64>>,
    /// Rotation range, degrees.
    pub degrees: (f64, f64),
    /// Shift range, metres.
    pub spread_m: f64,
    /// Print JSON.
    pub json: bool,
}

#[derive(Serialize)]
struct PlannedJson {
    joints: [f64; 6],
    pose: [f64; 6],
    rotation_deg: f64,
}

#[derive(Serialize)]
struct PlanJson {
    current: [f64; 6],
    poses: Vec<PlannedJson>,
    tour_time_s: f64,
}

/// `calibrate plan`.
pub fn plan_cmd(out: &mut dyn Write, args: &PlanArgs) -> Result<()> {
    let flange_arm = args.arm.with_tool(Isometry3::identity());
    let current = match args.current {
        Some(q) => q,
        None => {
            flange_arm
                .ik_closest(&args.center, &[0.0; 6], &Selection::default())
                .context("--center: the centre pose itself is not reachable")?
                .joints
        }
    };
    let mut o = PlanOptions::new(args.count, args.center, current);
    o.rotation_range_rad = (args.degrees.0.to_radians(), args.degrees.1.to_radians());
    o.translation_spread_m = args.spread_m;
    if let Some(m) = args.marker {
        o.flange_from_marker = m;
    }
    o.tracker = args.tracker.map(TrackerView::typical);
    let poses = plan(&args.arm, &o)?;
    let tour = tour_time(&args.arm, &current, &poses);
    if args.json {
        let j = PlanJson {
            current,
            poses: poses
                .iter()
                .map(|p| PlannedJson {
                    joints: p.joints,
                    pose: ur_pose_from_iso(&p.base_from_flange),
                    rotation_deg: p.rotation_rad.to_degrees(),
                })
                .collect(),
            tour_time_s: tour,
        };
        writeln!(out, "{}", serde_json::to_string(&j)?)?;
        return Ok(());
    }
    writeln!(
        out,
        "{} calibration poses for {} from [{}] (radians; flange pose in m, rotation vector)",
        poses.len(),
        args.arm.model(),
        crate::print::row(&current)
    )?;
    for (i, p) in poses.iter().enumerate() {
        writeln!(
            out,
            "{:>3}  q [{}]  pose [{}]  {:>5.1}°",
            i + 1,
            crate::print::row(&p.joints),
            crate::print::row(&ur_pose_from_iso(&p.base_from_flange)),
            p.rotation_rad.to_degrees()
        )?;
    }
    writeln!(
        out,
        "moves at full joint speed: {tour:.1} s in all{}",
        if args.tracker.is_some() {
            "; every marker pose inside the tracker's view"
        } else {
            "; no --tracker given, visibility not checked"
        }
    )?;
    Ok(())
}

/// Options of `calibrate synth`.
#[derive(Debug)]
pub struct SynthArgs<'a> {
    /// Where to write the pairs file.
    pub out_file: &'a Path,
    /// What to synthesise.
    pub options: SynthOptions,
}

/// `calibrate synth`.
pub fn synth_cmd(out: &mut dyn Write, args: &SynthArgs<'_>) -> Result<()> {
    let pairs = synthesize(&args.options)?;
    let mut text = String::new();
    let o = &args.options;
    text.push_str(&format!(
        "# mocomp synthetic calibration pairs: seed {}, {} pairs\n# true X = flange_from_marker: {:?}\n# true Y = base_from_tracker: {:?}\n",
        o.seed,
        o.count,
        ur_pose_from_iso(&o.flange_from_marker),
        ur_pose_from_iso(&o.base_from_tracker)
    ));
    text.push_str(&write_pairs_csv(&pairs, PairsFormat::Pose)?);
    std::fs::write(args.out_file, text)
        .with_context(|| format!("--out {}: cannot write", args.out_file.display()))?;
    writeln!(
        out,
        "wrote {} pairs to {}",
        pairs.len(),
        args.out_file.display()
    )?;
    crate::print::transform(
        out,
        "true X = flange_from_marker",
        &o.flange_from_marker,
        true,
    )?;
    crate::print::transform(
        out,
        "true Y = base_from_tracker",
        &o.base_from_tracker,
        true,
    )?;
    Ok(())
}
