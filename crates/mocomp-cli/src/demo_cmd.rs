//! `mocomp demo`: the paper's two-robot experiment on the simulated world (see
//! `mocomp_sim::experiment`), both controllers on the same trajectory, with a progress bar;
//! writes a CSV of every tick, the figures, `summary.md` and the configuration it ran with, and
//! prints the summary table.
//!
//! Settings come from the defaults, then `--config FILE` (see `mocomp_sim::config`), then the
//! command-line options; `--print-config` prints the result as a file instead of running.

use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use mocomp_geom::units::{deg_to_rad, m_to_mm, mm_to_m, rad_to_deg};
use mocomp_kin::Model;
use mocomp_sim::HeadMotion;
use mocomp_sim::config::{ExperimentFile, apply_toml};
use mocomp_sim::experiment::{
    Controller, ExperimentConfig, ExperimentError, Outcome, Phase, run_experiment,
};
use serde::Serialize;
use std::io::Write;
use std::net::IpAddr;
use std::path::PathBuf;

/// `mocomp demo`'s options. Unset options keep the configuration file's value, or the default.
#[derive(Debug, Clone, Args)]
pub struct DemoArgs {
    /// A configuration file (TOML; `--print-config` prints every key with its default).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print the configuration as a file (defaults, the file and the options applied) and exit.
    #[arg(long)]
    pub print_config: bool,
    /// Output directory.
    #[arg(long, default_value = "mocomp-demo")]
    pub out: PathBuf,
    /// Print the summary as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Compensation time per controller, seconds [30].
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Seed of the random motion and the tracker noise [1].
    #[arg(long)]
    pub seed: Option<u64>,
    /// The head's motion, with its defaults: smooth random motion, a slow drift, nods and turns
    /// (patient-like), or still [random].
    // Not "turn": the demo's head robot (a UR5 holding the phantom) cannot turn the head at those
    // speeds (C204A3 on its elbow); `mocomp run`'s simulated tracker can.
    #[arg(long, value_parser = ["random", "drift", "nods", "still"], conflicts_with = "motion_file")]
    pub motion: Option<String>,
    /// Replay a recorded head motion: a CSV file `t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz` (a tracker's
    /// head poses; irregular sample times are interpolated), taken relative to its first sample
    /// in the head's own frame and applied to the head at rest from t = 1 s.
    #[arg(long, value_name = "FILE")]
    pub motion_file: Option<PathBuf>,
    /// The head's translational speed, mm/s: the bound of random motion, the speed of a drift,
    /// the peak of nods [random: 20].
    #[arg(long, value_name = "MM_PER_S")]
    pub speed_mm_s: Option<f64>,
    /// The head's angular speed, degrees/s, in the same sense [random: 10].
    #[arg(long, value_name = "DEG_PER_S")]
    pub speed_deg_s: Option<f64>,
    /// The robot carrying the coil (U1) [ur3].
    #[arg(long, value_parser = crate::args::model)]
    pub coil_robot: Option<Model>,
    /// The robot carrying the head phantom (U2), of the same series as U1 [ur5].
    #[arg(long, value_parser = crate::args::model)]
    pub head_robot: Option<Model>,
    /// U1's loopback address [127.0.0.2].
    #[arg(long)]
    pub coil_host: Option<IpAddr>,
    /// U2's loopback address [127.0.0.3].
    #[arg(long)]
    pub head_host: Option<IpAddr>,
    /// Tracker samples per second [60].
    #[arg(long, value_name = "HZ")]
    pub tracker_rate_hz: Option<f64>,
    /// Tracker latency, acquisition to sending, ms [20].
    #[arg(long, value_name = "MS")]
    pub tracker_latency_ms: Option<f64>,
    /// Tracker position noise, 1σ per axis, mm [0.1].
    #[arg(long, value_name = "MM")]
    pub tracker_noise_mm: Option<f64>,
    /// Tracker rotation noise, 1σ per axis, degrees [0.057].
    #[arg(long, value_name = "DEG")]
    pub tracker_noise_deg: Option<f64>,
    /// Tracker dropouts per second (each `dropout_s` long, 0.1 s by default) [0].
    #[arg(long, value_name = "PER_S")]
    pub tracker_dropouts_per_s: Option<f64>,
    /// The `paper` controller's loop period, ms [100].
    #[arg(long, value_name = "MS")]
    pub paper_period_ms: Option<f64>,
    /// The `paper` controller's delay from sample to command, ms [80].
    #[arg(long, value_name = "MS")]
    pub paper_delay_ms: Option<f64>,
}

/// A configuration error as a usage error (exit 2), naming the key or option.
fn usage(e: ExperimentError) -> anyhow::Error {
    match e {
        ExperimentError::Config(m) => crate::UsageError(m).into(),
        other => other.into(),
    }
}

/// The configuration: defaults, then the file, then the options.
pub fn configuration(a: &DemoArgs) -> anyhow::Result<ExperimentConfig> {
    let mut cfg = ExperimentConfig::new()?;
    if let Some(path) = &a.config {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("--config {}", path.display()))?;
        apply_toml(&text, &mut cfg)
            .map_err(|e| crate::UsageError(format!("{}: {e}", path.display())))?;
        // A recorded motion's file is relative to the configuration's directory.
        let dir = path.parent().unwrap_or(std::path::Path::new(""));
        cfg.motion
            .load_file(dir)
            .map_err(|e| crate::UsageError(format!("{}: motion.path: {e}", path.display())))?;
    }
    let opt = |flag: &str, e: String| crate::UsageError(format!("--{flag}: {e}"));
    if let Some(s) = a.seconds {
        cfg.duration_s = s;
    }
    if let Some(file) = &a.motion_file {
        cfg.motion = HeadMotion::from_file(&file.to_string_lossy(), std::path::Path::new(""))
            .map_err(|e| opt("motion-file", e.to_string()))?;
    }
    if let Some(kind) = &a.motion
        && cfg.motion.name() != kind
    {
        cfg.motion = HeadMotion::named(kind)
            .ok_or_else(|| opt("motion", format!("{kind:?} is not a motion")))?;
        // The new motion takes the run's seed.
        let seed = cfg.tracker.seed;
        cfg.set_seed(seed);
    }
    if a.speed_mm_s.is_some() || a.speed_deg_s.is_some() {
        cfg.motion = cfg
            .motion
            .with_speeds(a.speed_mm_s.map(mm_to_m), a.speed_deg_s.map(deg_to_rad))
            .map_err(|e| {
                let flag = if e.key == "angular_rad_s" {
                    "speed-deg-s"
                } else {
                    "speed-mm-s"
                };
                opt(flag, e.problem.to_string())
            })?;
    }
    if let Some(seed) = a.seed {
        cfg.set_seed(seed);
    }
    if let Some(m) = a.coil_robot {
        cfg.coil_robot = m;
    }
    if let Some(m) = a.head_robot {
        cfg.head_robot = m;
    }
    if let Some(h) = a.coil_host {
        cfg.coil_host = h;
    }
    if let Some(h) = a.head_host {
        cfg.head_host = h;
    }
    let t = &mut cfg.tracker;
    if let Some(v) = a.tracker_rate_hz {
        t.rate_hz = v;
    }
    if let Some(v) = a.tracker_latency_ms {
        t.latency_s = v * 1e-3;
    }
    if let Some(v) = a.tracker_noise_mm {
        t.noise_m = mm_to_m(v);
    }
    if let Some(v) = a.tracker_noise_deg {
        t.noise_rad = deg_to_rad(v);
    }
    if let Some(v) = a.tracker_dropouts_per_s {
        t.dropouts_per_s = v;
    }
    if let Some(v) = a.paper_period_ms {
        cfg.paper.period_s = v * 1e-3;
    }
    if let Some(v) = a.paper_delay_ms {
        cfg.paper.compute_delay_s = v * 1e-3;
    }
    cfg.validate().map_err(usage)?;
    Ok(cfg)
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
    holds: usize,
    retreats: usize,
    dropouts_coasted: usize,
    outliers_rejected: usize,
    /// The true coil's least distance to the head model (negative: inside), mm.
    min_clearance_mm: f64,
    /// Time the true coil spent inside the head model, s.
    inside_head_s: f64,
}

#[derive(Serialize)]
struct Summary {
    seconds: f64,
    seed: u64,
    /// still, drift, nods or random.
    motion: &'static str,
    coil_robot: &'static str,
    head_robot: &'static str,
    head_peak_mm_s: f64,
    head_peak_deg_s: f64,
    tracker_rate_hz: f64,
    tracker_latency_ms: f64,
    tracker_noise_mm: f64,
    tracker_noise_deg: f64,
    tracker_dropouts_per_s: f64,
    controllers: Vec<Row>,
    /// paper ÷ mocomp, per statistic of d.
    ratio_d_rms: f64,
    ratio_d_max: f64,
}

fn summary(o: &Outcome, cfg: &ExperimentConfig) -> Summary {
    let rows: Vec<Row> = o
        .runs
        .iter()
        .map(|r| {
            let n = crate::plots::event_counts(r);
            Row {
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
                holds: n.holds,
                retreats: n.retreats,
                dropouts_coasted: n.coasts,
                outliers_rejected: n.outliers,
                min_clearance_mm: m_to_mm(r.min_clearance_m),
                inside_head_s: r.inside_head_s,
            }
        })
        .collect();
    let (p, m) = (&rows[0], &rows[rows.len() - 1]);
    Summary {
        seconds: cfg.duration_s,
        seed: cfg.tracker.seed,
        motion: cfg.motion.name(),
        coil_robot: cfg.coil_robot.name(),
        head_robot: cfg.head_robot.name(),
        head_peak_mm_s: m_to_mm(o.head_peak_speed.0),
        head_peak_deg_s: rad_to_deg(o.head_peak_speed.1),
        tracker_rate_hz: cfg.tracker.rate_hz,
        tracker_latency_ms: cfg.tracker.latency_s * 1e3,
        tracker_noise_mm: m_to_mm(cfg.tracker.noise_m),
        tracker_noise_deg: rad_to_deg(cfg.tracker.noise_rad),
        tracker_dropouts_per_s: cfg.tracker.dropouts_per_s,
        ratio_d_rms: p.d_rms / m.d_rms,
        ratio_d_max: p.d_max / m.d_max,
        controllers: rows,
    }
}

/// The motion, in words.
fn motion_words(m: &HeadMotion) -> &'static str {
    match m {
        HeadMotion::Still => "a still head",
        HeadMotion::Drift(_) => "a slow drift of the head",
        HeadMotion::Nods(_) => "nods and turns of the head",
        HeadMotion::Random(_) => "smooth random head motion",
        HeadMotion::Turn(_) => "a quick head turn away and back",
        HeadMotion::File(_) => "a recorded head motion",
    }
}

fn markdown(s: &Summary, o: &Outcome, cfg: &ExperimentConfig) -> String {
    let mut t = String::new();
    t.push_str(
        "# mocomp demo: the paper's experiment

",
    );
    t.push_str(&format!(
        "{:.0} s of {} (peaks {:.1} mm/s and {:.1}°/s) per controller; the {} carries the coil, the {} the head phantom. Tracker: {:.0} Hz, {:.0} ms latency, noise {:.2} mm and {:.3}° (1σ per axis), {} dropouts/s; seed {}. d = ‖E2_T_E1,g − E2_T_E1‖_F, translation in mm.\n\n",
        s.seconds,
        motion_words(&cfg.motion),
        s.head_peak_mm_s,
        s.head_peak_deg_s,
        s.coil_robot.to_uppercase(),
        s.head_robot.to_uppercase(),
        s.tracker_rate_hz,
        s.tracker_latency_ms,
        s.tracker_noise_mm,
        s.tracker_noise_deg,
        s.tracker_dropouts_per_s,
        s.seed,
    ));
    t.push_str("| controller | d RMS | d p95 | d max | translation RMS (mm) | p95 | max | rotation RMS (°) | p95 | max | holds | retreats | dropouts coasted | outliers rejected | least coil clearance (mm) | coil in the head (s) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &s.controllers {
        t.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {} | {:.2} | {:.2} |\n",
            r.controller,
            r.d_rms,
            r.d_p95,
            r.d_max,
            r.translation_mm_rms,
            r.translation_mm_p95,
            r.translation_mm_max,
            r.rotation_deg_rms,
            r.rotation_deg_p95,
            r.rotation_deg_max,
            r.holds,
            r.retreats,
            r.dropouts_coasted,
            r.outliers_rejected,
            r.min_clearance_mm,
            r.inside_head_s,
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
        m_to_mm(c.y_error.0),
        rad_to_deg(c.y_error.1),
        m_to_mm(c.x_error.0),
        rad_to_deg(c.x_error.1),
        cfg.paper.period_s * 1e3,
        cfg.paper.compute_delay_s * 1e3,
        cfg.paper.joint_speed_rad_s,
        cfg.paper.joint_accel_rad_s2
    ));
    t
}

/// Runs the demo (or prints its configuration).
pub fn demo(out: &mut dyn Write, opts: &DemoArgs) -> anyhow::Result<()> {
    let cfg = configuration(opts)?;
    let file = ExperimentFile::from_config(&cfg).to_toml()?;
    if opts.print_config {
        write!(out, "{file}")?;
        return Ok(());
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
    let s = summary(&outcome, &cfg);
    // Every tick of both controllers.
    let csv_path = opts.out.join("demo.csv");
    let mut csv = String::from(
        "controller,t_s,d,translation_mm,rotation_deg,head_speed_mm_s,head_speed_deg_s,sample_age_ms,horizon_ms,coil_clearance_mm,mode,event\n",
    );
    for r in &outcome.runs {
        for x in &r.records {
            csv.push_str(&format!(
                "{},{:.4},{:.5},{:.5},{:.5},{:.3},{:.3},{:.3},{:.3},{:.3},{},{}\n",
                r.controller.name(),
                x.t,
                x.d,
                x.translation_m * 1e3,
                x.rotation_rad.to_degrees(),
                x.head_speed.0 * 1e3,
                x.head_speed.1.to_degrees(),
                x.sample_age_s * 1e3,
                x.horizon_s * 1e3,
                m_to_mm(x.coil_clearance_m),
                format!("{:?}", x.mode).replace(',', ";"),
                x.event
                    .map(|e| format!("{e:?}").replace(',', ";"))
                    .unwrap_or_default()
            ));
        }
    }
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    // The configuration it ran with: `--config` with it repeats the run.
    let cfg_path = opts.out.join("config.toml");
    std::fs::write(&cfg_path, &file).with_context(|| format!("writing {}", cfg_path.display()))?;
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
            "\nwrote {}, {}, {} and {} figures (PNG and SVG: {}) in {}",
            csv_path.display(),
            md_path.display(),
            cfg_path.display(),
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
