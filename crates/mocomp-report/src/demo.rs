//! The experiment's written record: the summary (JSON and Markdown), the CSV of every tick, and
//! the figures ([`crate::plots`]), in one directory.

use mocomp_experiment::experiment::{Controller, ExperimentConfig, LoggedPulse, Outcome, Run};
use mocomp_experiment::head_drive::Lag;
use mocomp_geom::units::{m_to_mm, rad_to_deg};
use mocomp_sim::HeadMotion;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// One controller's figures.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    /// Its name (`paper`, `mocomp`).
    pub controller: &'static str,
    /// d = ‖E2_T_E1,g − E2_T_E1‖_F (translation in mm): RMS over the run.
    pub d_rms: f64,
    /// d: 95th percentile.
    pub d_p95: f64,
    /// d: largest.
    pub d_max: f64,
    /// Translation error of E2_T_E1, mm: RMS.
    pub translation_mm_rms: f64,
    /// The same, 95th percentile.
    pub translation_mm_p95: f64,
    /// The same, largest.
    pub translation_mm_max: f64,
    /// Rotation error of E2_T_E1, degrees: RMS.
    pub rotation_deg_rms: f64,
    /// The same, 95th percentile.
    pub rotation_deg_p95: f64,
    /// The same, largest.
    pub rotation_deg_max: f64,
    /// Holds.
    pub holds: usize,
    /// Retreats.
    pub retreats: usize,
    /// Tracker dropouts coasted through on the prediction.
    pub dropouts_coasted: usize,
    /// Tracker samples rejected as outliers.
    pub outliers_rejected: usize,
    /// The true coil's least distance to the head model (negative: inside), mm.
    pub min_clearance_mm: f64,
    /// Time the true coil spent inside the head model, s.
    pub inside_head_s: f64,
    /// The force of the true coil on the scalp (the simulated contact), N: largest.
    pub contact_force_n_max: f64,
    /// The same: RMS over the run.
    pub contact_force_n_rms: f64,
    /// With `--tracker-bump-at-s`: how long after the bump the drift monitor called the
    /// calibration invalid, s (null: no bump, or never).
    pub tracker_bump_detected_s: Option<f64>,
    /// The prediction's share of the coil's error, mm: the coil aimed for each tick against the
    /// goal on the true head then (null where nothing predicted: the paper's pipeline).
    pub prediction_mm: Option<ShareStats>,
    /// The execution's share, mm: the coil against the one aimed for that tick.
    pub execution_mm: Option<ShareStats>,
    /// d less the oracle's, when the oracle ran: what any better controller could still win.
    pub excess_over_oracle: Option<Excess>,
    /// With a coil model: the dose at the target against the planned, |error| in % of the
    /// planned, RMS over the run (absent without a model).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dose_error_pct_rms: Option<f64>,
    /// The same, 95th percentile.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dose_error_pct_p95: Option<f64>,
    /// The same, largest.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dose_error_pct_max: Option<f64>,
    /// With a pulsing session (`--pulses-hz`, mocomp's run): the stimulator's pulses (absent
    /// without).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pulses: Option<PulseScore>,
}

/// A run's pulses through the gate, scored by the truth: the true coil against the goal on the
/// true head, and the dose it gave the target.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct PulseScore {
    /// Pulses the gate let through.
    pub through_gate: usize,
    /// Tries the shut gate withheld.
    pub withheld: usize,
    /// The true coil's largest distance from the goal at a pulse, mm.
    pub error_mm_max: f64,
    /// Its largest angle from the goal at a pulse, degrees.
    pub error_deg_max: f64,
    /// With a coil model: the largest |dose − planned| at a pulse, % of the planned.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dose_error_pct_max: Option<f64>,
}

/// `r`'s pulses through the gate, where its run had a session (`cfg`'s, mocomp's run).
fn pulse_score(r: &Run, cfg: &ExperimentConfig) -> Option<PulseScore> {
    if cfg.session.is_none() || r.controller != Controller::Mocomp {
        return None;
    }
    let gated: Vec<_> = r.pulses.iter().filter(|p| !p.by_hand).collect();
    // A NaN (a pulse nothing could score) is not hidden by the others.
    let most = |f: &dyn Fn(&&LoggedPulse) -> f64| {
        gated.iter().map(f).fold(0.0, |a: f64, b| {
            if a.is_nan() || b.is_nan() {
                f64::NAN
            } else {
                a.max(b)
            }
        })
    };
    Some(PulseScore {
        through_gate: gated.len(),
        withheld: r.withheld_pulses,
        error_mm_max: m_to_mm(most(&|p| p.truth.0)),
        error_deg_max: rad_to_deg(most(&|p| p.truth.1)),
        dose_error_pct_max: cfg
            .dose
            .is_some()
            .then(|| most(&|p| (p.dose_pct - 100.0).abs())),
    })
}

/// A share of the error: RMS and 95th percentile, mm.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ShareStats {
    /// Root mean square.
    pub rms: f64,
    /// 95th percentile.
    pub p95: f64,
}

/// A controller's d beyond the oracle's.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Excess {
    /// d RMS less the oracle's.
    pub d_rms: f64,
    /// d max less the oracle's.
    pub d_max: f64,
    /// Translation RMS less the oracle's, mm.
    pub translation_mm_rms: f64,
}

/// The experiment's summary (`mocomp demo --json`).
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Compensation time per controller, s.
    pub seconds: f64,
    /// The tracker noise's seed.
    pub seed: u64,
    /// still, drift, nods or random.
    pub motion: &'static str,
    /// U1, carrying the coil.
    pub coil_robot: &'static str,
    /// U2, carrying the head phantom.
    pub head_robot: &'static str,
    /// The head's peak speed, mm/s.
    pub head_peak_mm_s: f64,
    /// The head's peak angular speed, °/s.
    pub head_peak_deg_s: f64,
    /// Tracker samples per second.
    pub tracker_rate_hz: f64,
    /// Tracker latency, acquisition to sending, ms.
    pub tracker_latency_ms: f64,
    /// Tracker position noise, 1σ per axis, mm.
    pub tracker_noise_mm: f64,
    /// Tracker rotation noise, 1σ per axis, degrees.
    pub tracker_noise_deg: f64,
    /// Tracker dropouts per second.
    pub tracker_dropouts_per_s: f64,
    /// One row per controller, in the order run.
    pub controllers: Vec<Row>,
    /// paper ÷ mocomp: d RMS (null unless both ran).
    pub ratio_d_rms: Option<f64>,
    /// paper ÷ mocomp: d max (null unless both ran).
    pub ratio_d_max: Option<f64>,
    /// Time the head robot could not follow the head's motion within its joint limits, s (the
    /// same in every run: the head robot plays the motion alone).
    pub head_robot_lagged_s: f64,
    /// Those intervals, with each one's largest joint error.
    pub head_robot_lags: Vec<Lag>,
}

/// The summary of an outcome.
pub fn summary(o: &Outcome, cfg: &ExperimentConfig) -> Summary {
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
                contact_force_n_max: r.contact_force_n.max,
                contact_force_n_rms: r.contact_force_n.rms,
                tracker_bump_detected_s: r.bump_detected_after_s,
                prediction_mm: share(&r.prediction_mm),
                execution_mm: share(&r.execution_mm),
                excess_over_oracle: None,
                dose_error_pct_rms: r.dose_error_pct.map(|d| d.rms),
                dose_error_pct_p95: r.dose_error_pct.map(|d| d.p95),
                dose_error_pct_max: r.dose_error_pct.map(|d| d.max),
                pulses: pulse_score(r, cfg),
            }
        })
        .collect();
    let mut rows = rows;
    let named = |rows: &[Row], name: &str| rows.iter().find(|r| r.controller == name).cloned();
    if let Some(o) = named(&rows, "oracle") {
        for r in rows.iter_mut().filter(|r| r.controller != "oracle") {
            r.excess_over_oracle = Some(Excess {
                d_rms: r.d_rms - o.d_rms,
                d_max: r.d_max - o.d_max,
                translation_mm_rms: r.translation_mm_rms - o.translation_mm_rms,
            });
        }
    }
    let ratio = match (named(&rows, "paper"), named(&rows, "mocomp")) {
        (Some(p), Some(m)) => Some((p.d_rms / m.d_rms, p.d_max / m.d_max)),
        _ => None,
    };
    let lags = o
        .runs
        .first()
        .map(|r| r.head_lags.clone())
        .unwrap_or_default();
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
        ratio_d_rms: ratio.map(|r| r.0),
        ratio_d_max: ratio.map(|r| r.1),
        head_robot_lagged_s: lags.iter().fold(0.0, |s, l| s + (l.to_s - l.from_s)),
        head_robot_lags: lags,
        controllers: rows,
    }
}

/// A share's figures, `None` where no tick had one.
fn share(s: &mocomp_experiment::experiment::Stats) -> Option<ShareStats> {
    s.rms.is_finite().then_some(ShareStats {
        rms: s.rms,
        p95: s.p95,
    })
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

/// The summary as Markdown (`summary.md`, and what `mocomp demo` prints).
pub fn markdown(s: &Summary, o: &Outcome, cfg: &ExperimentConfig) -> String {
    let mut t = heading(s, cfg);
    t.push_str(&controller_table(s));
    t.push('\n');
    t.push_str(&dose_table(s, cfg));
    t.push_str(&pulse_lines(s));
    t.push_str(&comparisons(s));
    t.push('\n');
    t.push_str(&head_lag(s));
    t.push_str(&bump_line(s, cfg));
    t.push_str(&calibration_line(o, cfg));
    t
}

/// The title, and what was run: the motion, the robots, the tracker, the seed.
fn heading(s: &Summary, cfg: &ExperimentConfig) -> String {
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
    t
}

/// A row per controller: `d`, its parts, the safety events, clearance, force, the error's split.
fn controller_table(s: &Summary) -> String {
    let mut t = String::new();
    t.push_str("| controller | d RMS | d p95 | d max | translation RMS (mm) | p95 | max | rotation RMS (°) | p95 | max | holds | retreats | dropouts coasted | outliers rejected | least coil clearance (mm) | coil in the head (s) | contact force max (N) | RMS (N) | prediction's share RMS (mm) | execution's share RMS (mm) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in &s.controllers {
        t.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} |\n",
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
            r.contact_force_n_max,
            r.contact_force_n_rms,
            r.prediction_mm
                .map_or("–".to_string(), |x| format!("{:.3}", x.rms)),
            r.execution_mm
                .map_or("–".to_string(), |x| format!("{:.3}", x.rms)),
        ));
    }
    t
}

/// The paper's controller against mocomp's, and each against the oracle.
fn comparisons(s: &Summary) -> String {
    let mut t = String::new();
    if let (Some(a), Some(b)) = (s.ratio_d_rms, s.ratio_d_max) {
        t.push_str(&format!("paper ÷ mocomp: d RMS {a:.1}×, d max {b:.1}×.\n"));
    }
    let excess: Vec<String> = s
        .controllers
        .iter()
        .filter_map(|r| {
            r.excess_over_oracle.map(|e| {
                format!(
                    "{} d RMS {:+.3}, d max {:+.3}",
                    r.controller, e.d_rms, e.d_max
                )
            })
        })
        .collect();
    if !excess.is_empty() {
        t.push_str(&format!(
            "Over the oracle (the same loop knowing the head's future, no latency: the least any controller could do on this robot): {}.\n",
            excess.join("; ")
        ));
    }
    t
}

/// Where the head robot could not play the motion, if anywhere.
fn head_lag(s: &Summary) -> String {
    let mut t = String::new();
    if let Some(worst) = s
        .head_robot_lags
        .iter()
        .max_by(|a, b| a.max_joint_rad.total_cmp(&b.max_joint_rad))
    {
        t.push_str(&format!(
            "The head moved faster than the {} can: it lagged the motion for {:.2} s in {} intervals (the worst {:.2}–{:.2} s, {:.2}° behind at a joint), within its joint speeds and {} rad/s² of acceleration. Every controller was scored on the head the robot played.\n\n",
            s.head_robot.to_uppercase(),
            s.head_robot_lagged_s,
            s.head_robot_lags.len(),
            worst.from_s,
            worst.to_s,
            rad_to_deg(worst.max_joint_rad),
            mocomp_experiment::head_drive::HEAD_ACCEL_RAD_S2,
        ));
    }
    t
}

/// The tracker's bump and when each run's drift monitor caught it, if bumped.
fn bump_line(s: &Summary, cfg: &ExperimentConfig) -> String {
    let mut t = String::new();
    if let Some((at, b)) = cfg.tracker_bump {
        t.push_str(&format!(
            "The tracker was bumped {at:.1} s into each run ({:.1} mm, {:.2}°). The drift monitor on the coil's marker called the calibration invalid after: {}.\n\n",
            m_to_mm(b.translation.vector.norm()),
            rad_to_deg(b.rotation.angle()),
            s.controllers
                .iter()
                .map(|r| format!(
                    "{} {}",
                    r.controller,
                    r.tracker_bump_detected_s
                        .map_or("never".to_string(), |d| format!("{:.3} s", d))
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    t
}

/// The coil robot's calibration against the truth, and the paper controller's settings.
fn calibration_line(o: &Outcome, cfg: &ExperimentConfig) -> String {
    let mut t = String::new();
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

/// The dose's table, when the experiment had a coil model (else nothing).
/// A line per run with pulses: how many the gate let through and how good the worst was.
fn pulse_lines(s: &Summary) -> String {
    let mut t = String::new();
    for r in &s.controllers {
        let Some(p) = r.pulses else { continue };
        t.push_str(&format!(
            "Pulses ({}): {} through the gate, {} withheld by it; at a pulse the true coil was at most {:.2} mm and {:.2}° from the goal{}.\n\n",
            r.controller,
            p.through_gate,
            p.withheld,
            p.error_mm_max,
            p.error_deg_max,
            p.dose_error_pct_max
                .map_or(String::new(), |d| format!(", the dose at most {d:.2} % from the planned"))
        ));
    }
    t
}

fn dose_table(s: &Summary, cfg: &ExperimentConfig) -> String {
    let Some(model) = &cfg.dose else {
        return String::new();
    };
    let mut t = format!(
        "The dose: the field the coil ({}, {} dipoles, {:.1} A/µs) gives at the target ({:.0} mm under the scalp on the goal's axis, in the sphere fitted to the scalp there), along the field the goal gives, against the goal's; |error| in % of it.\n\n| controller | dose error RMS (%) | p95 | max |\n|---|---|---|---|\n",
        model.coil.name.as_deref().unwrap_or("model"),
        model.coil.len(),
        model.didt_a_per_s * 1e-6,
        m_to_mm(model.depth_m),
    );
    for r in &s.controllers {
        let f = |v: Option<f64>| v.map_or("–".to_string(), |x| format!("{x:.2}"));
        t.push_str(&format!(
            "| {} | {} | {} | {} |\n",
            r.controller,
            f(r.dose_error_pct_rms),
            f(r.dose_error_pct_p95),
            f(r.dose_error_pct_max)
        ));
    }
    t.push('\n');
    t
}

/// The CSV of every tick of every controller (`demo.csv`), on the `csv` crate: a mode or event
/// whose text holds a comma is quoted.
pub fn ticks_csv(o: &Outcome) -> Result<Vec<u8>, csv::Error> {
    let mut w = csv::Writer::from_writer(Vec::new());
    // The dose's column only with a coil model: without one the file is as it always was.
    let dose = o
        .runs
        .iter()
        .any(|r| r.records.iter().any(|x| x.dose_pct.is_finite()));
    let mut header = vec![
        "controller",
        "t_s",
        "d",
        "translation_mm",
        "rotation_deg",
        "head_speed_mm_s",
        "head_speed_deg_s",
        "sample_age_ms",
        "horizon_ms",
        "coil_clearance_mm",
        "contact_force_n",
        "mode",
        "event",
        "drift",
        "prediction_mm",
        "execution_mm",
        "standoff_mm",
    ];
    if dose {
        header.push("dose_pct");
    }
    w.write_record(&header)?;
    for r in &o.runs {
        for x in &r.records {
            let mut row = vec![
                r.controller.name().to_string(),
                format!("{:.4}", x.t),
                format!("{:.5}", x.d),
                format!("{:.5}", x.translation_m * 1e3),
                format!("{:.5}", x.rotation_rad.to_degrees()),
                format!("{:.3}", x.head_speed.0 * 1e3),
                format!("{:.3}", x.head_speed.1.to_degrees()),
                format!("{:.3}", x.sample_age_s * 1e3),
                format!("{:.3}", x.horizon_s * 1e3),
                format!("{:.3}", m_to_mm(x.coil_clearance_m)),
                format!("{:.3}", x.contact_force_n),
                format!("{:?}", x.mode),
                x.event.map(|e| format!("{e:?}")).unwrap_or_default(),
                x.drift.map(|d| format!("{d:?}")).unwrap_or_default(),
                format!("{:.4}", x.prediction_m * 1e3),
                format!("{:.4}", x.execution_m * 1e3),
                format!("{:.4}", x.standoff_m * 1e3),
            ];
            if dose {
                row.push(format!("{:.4}", x.dose_pct));
            }
            w.write_record(&row)?;
        }
    }
    w.into_inner().map_err(|e| e.into_error().into())
}

/// What [`write`] wrote.
#[derive(Debug, Clone)]
pub struct Written {
    /// The summary.
    pub summary: Summary,
    /// The same as Markdown.
    pub markdown: String,
    /// `demo.csv`.
    pub csv: PathBuf,
    /// `summary.md`.
    pub markdown_path: PathBuf,
    /// `config.toml`.
    pub config: PathBuf,
    /// The figures, PNG and SVG of each.
    pub figures: Vec<PathBuf>,
}

impl Written {
    /// The line that says what was written where (`dir`, the output directory).
    pub fn files_line(&self, dir: &Path) -> String {
        let names: Vec<&str> = self
            .figures
            .iter()
            .filter_map(|f| f.file_stem()?.to_str())
            .step_by(2)
            .collect();
        format!(
            "wrote {}, {}, {} and {} figures (PNG and SVG: {}) in {}",
            self.csv.display(),
            self.markdown_path.display(),
            self.config.display(),
            self.figures.len() / 2,
            names.join(", "),
            dir.display()
        )
    }
}

/// Why the record could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A file could not be written.
    #[error("writing {path}")]
    Io {
        /// Which.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The CSV could not be formatted.
    #[error("formatting demo.csv")]
    Csv(#[from] csv::Error),
    /// A figure could not be drawn.
    #[error(transparent)]
    Plot(#[from] crate::plots::PlotError),
}

/// Writes the record of `o` into `dir` (which must exist): `demo.csv`, the figures,
/// `summary.md`, and `config` (the configuration it ran with, as a file) as `config.toml`.
pub fn write(
    o: &Outcome,
    cfg: &ExperimentConfig,
    config: &str,
    dir: &Path,
) -> Result<Written, ReportError> {
    let put = |name: &str, bytes: &[u8]| {
        let path = dir.join(name);
        std::fs::write(&path, bytes)
            .map(|()| path.clone())
            .map_err(|source| ReportError::Io { path, source })
    };
    let summary = summary(o, cfg);
    let csv = put("demo.csv", &ticks_csv(o)?)?;
    let config = put("config.toml", config.as_bytes())?;
    let figures = crate::plots::write_all(&o.runs, cfg.duration_s, dir)?;
    let markdown = markdown(&summary, o, cfg);
    let markdown_path = put("summary.md", markdown.as_bytes())?;
    Ok(Written {
        summary,
        markdown,
        csv,
        markdown_path,
        config,
        figures,
    })
}
