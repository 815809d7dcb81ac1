//! `mocomp demo [--out DIR] [--json] [--seconds S] [--seed N]`: the paper's two-robot experiment
//! on the simulated world (see `mocomp_sim::experiment`), both controllers on the same trajectory,
//! with a progress bar; writes a CSV of every tick and `summary.md`, prints the summary table.

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use mocomp_sim::experiment::{Controller, ExperimentConfig, Outcome, Phase, run_experiment};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

/// Options from the command line.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    /// Output directory.
    pub out: PathBuf,
    /// Print the summary as JSON.
    pub json: bool,
    /// Compensation time per controller, s.
    pub seconds: f64,
    /// Seed of the head motion and the tracker noise.
    pub seed: u64,
    /// No progress bar.
    pub quiet: bool,
    /// Loopback addresses of the coil robot and the head robot.
    pub hosts: (std::net::IpAddr, std::net::IpAddr),
}

#[derive(Serialize)]
struct Row {
    controller: &'static str,
    d_rms: f64,
    d_p95: f64,
    d_max: f64,
    translation_mm_rms: f64,
    translation_mm_p95: f64,
    translation_mm_max: f64,
    rotation_deg_rms: f64,
    rotation_deg_p95: f64,
    rotation_deg_max: f64,
}

#[derive(Serialize)]
struct Summary {
    seconds: f64,
    seed: u64,
    head_peak_mm_s: f64,
    head_peak_deg_s: f64,
    controllers: Vec<Row>,
    /// paper ÷ mocomp, per statistic of d.
    ratio_d_rms: f64,
    ratio_d_max: f64,
}

fn summary(o: &Outcome, seconds: f64, seed: u64) -> Summary {
    let rows: Vec<Row> = o
        .runs
        .iter()
        .map(|r| Row {
            controller: r.controller.name(),
            d_rms: r.d.rms,
            d_p95: r.d.p95,
            d_max: r.d.max,
            translation_mm_rms: r.translation_mm.rms,
            translation_mm_p95: r.translation_mm.p95,
            translation_mm_max: r.translation_mm.max,
            rotation_deg_rms: r.rotation_deg.rms,
            rotation_deg_p95: r.rotation_deg.p95,
            rotation_deg_max: r.rotation_deg.max,
        })
        .collect();
    let (p, m) = (&rows[0], &rows[rows.len() - 1]);
    Summary {
        seconds,
        seed,
        head_peak_mm_s: o.head_peak_speed.0 * 1e3,
        head_peak_deg_s: o.head_peak_speed.1.to_degrees(),
        ratio_d_rms: p.d_rms / m.d_rms,
        ratio_d_max: p.d_max / m.d_max,
        controllers: rows,
    }
}

fn markdown(s: &Summary, o: &Outcome, cfg: &ExperimentConfig) -> String {
    let mut t = String::new();
    t.push_str("# mocomp demo: the paper's experiment\n\n");
    t.push_str(&format!(
        "{:.0} s of smooth random head motion (seed {}, peaks {:.1} mm/s and {:.1}°/s) per controller. d = ‖E2_T_E1,g − E2_T_E1‖_F, translation in mm.\n\n",
        s.seconds, s.seed, s.head_peak_mm_s, s.head_peak_deg_s
    ));
    t.push_str("| controller | d RMS | d p95 | d max | translation RMS (mm) | p95 | max | rotation RMS (°) | p95 | max |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &s.controllers {
        t.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |\n",
            r.controller,
            r.d_rms,
            r.d_p95,
            r.d_max,
            r.translation_mm_rms,
            r.translation_mm_p95,
            r.translation_mm_max,
            r.rotation_deg_rms,
            r.rotation_deg_p95,
            r.rotation_deg_max
        ));
    }
    t.push_str(&format!(
        "\npaper ÷ mocomp: d RMS {:.1}×, d max {:.1}×.\n\n",
        s.ratio_d_rms, s.ratio_d_max
    ));
    let c = &o.coil_calibration;
    t.push_str(&format!(
        "Calibration of the coil robot ({} pairs): Y {:.3} mm, {:.4}°; X {:.3} mm, {:.4}° from the truth. The `paper` controller: a {:.0} ms loop, {:.0} ms from sample to command, movej at {} rad/s and {} rad/s² to the least-angle-sum IK solution, no prediction.\n",
        c.pairs,
        c.y_error.0 * 1e3,
        c.y_error.1.to_degrees(),
        c.x_error.0 * 1e3,
        c.x_error.1.to_degrees(),
        cfg.paper.period_s * 1e3,
        cfg.paper.compute_delay_s * 1e3,
        cfg.paper.joint_speed_rad_s,
        cfg.paper.joint_accel_rad_s2
    ));
    t
}

/// Runs the demo.
pub fn demo(out: &mut dyn Write, opts: &DemoOptions) -> anyhow::Result<()> {
    if !(opts.seconds.is_finite() && opts.seconds > 0.0 && opts.seconds <= 600.0) {
        return Err(
            crate::UsageError(format!("--seconds {}: must be in (0, 600]", opts.seconds)).into(),
        );
    }
    let mut cfg = ExperimentConfig::new()?;
    cfg.duration_s = opts.seconds;
    (cfg.coil_host, cfg.head_host) = opts.hosts;
    cfg.tracker.seed = opts.seed;
    if let mocomp_sim::HeadMotion::Random(r) = &mut cfg.motion {
        r.seed = opts.seed;
    }
    std::fs::create_dir_all(&opts.out).with_context(|| format!("--out {}", opts.out.display()))?;
    let bar = if opts.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(1000)
    };
    bar.set_style(
        ProgressStyle::with_template("{prefix:>28} [{bar:30}] {percent:>3}% {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let outcome = run_experiment(
        &cfg,
        &[Controller::Paper, Controller::Mocomp],
        &mut |phase, f| {
            let name = match phase {
                Phase::Connecting => "starting the simulators".to_string(),
                Phase::CalibratingCoilRobot => "calibrating the coil robot".to_string(),
                Phase::CalibratingHeadRobot => "calibrating the head robot".to_string(),
                Phase::Compensating(c) => format!("compensating: {}", c.name()),
            };
            bar.set_prefix(name);
            bar.set_position((f * 1000.0) as u64);
        },
    )?;
    bar.finish_and_clear();
    let s = summary(&outcome, opts.seconds, opts.seed);
    // Every tick of both controllers.
    let csv_path = opts.out.join("demo.csv");
    let mut csv = String::from(
        "controller,t_s,d,translation_mm,rotation_deg,head_speed_mm_s,head_speed_deg_s,sample_age_ms,horizon_ms,mode,event\n",
    );
    for r in &outcome.runs {
        for x in &r.records {
            csv.push_str(&format!(
                "{},{:.4},{:.5},{:.5},{:.5},{:.3},{:.3},{:.3},{:.3},{},{}\n",
                r.controller.name(),
                x.t,
                x.d,
                x.translation_m * 1e3,
                x.rotation_rad.to_degrees(),
                x.head_speed.0 * 1e3,
                x.head_speed.1.to_degrees(),
                x.sample_age_s * 1e3,
                x.horizon_s * 1e3,
                format!("{:?}", x.mode).replace(',', ";"),
                x.event
                    .map(|e| format!("{e:?}").replace(',', ";"))
                    .unwrap_or_default()
            ));
        }
    }
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    let figures = crate::plots::write_all(&outcome.runs, cfg.duration_s, &opts.out)?;
    let md = markdown(&s, &outcome, &cfg);
    let md_path = opts.out.join("summary.md");
    std::fs::write(&md_path, &md).with_context(|| format!("writing {}", md_path.display()))?;
    if opts.json {
        writeln!(out, "{}", serde_json::to_string(&s)?)?;
    } else {
        write!(out, "{md}")?;
        writeln!(
            out,
            "\nwrote {}, {} and {} figures (PNG and SVG: {}) in {}",
            csv_path.display(),
            md_path.display(),
            figures.len() / 2,
            figures
                .iter()
                .filter_map(|f| f.file_stem()?.to_str())
                .step_by(2)
                .collect::<Vec<_>>()
                .join(", "),
            opts.out.display()
        )?;
    }
    Ok(())
}
