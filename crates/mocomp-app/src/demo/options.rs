//! `mocomp demo`'s settings: the defaults, then a configuration file, then what the command line
//! overrides ([`DemoOverrides`], in SI units: the command line converts its millimetres,
//! milliseconds and degrees at its edge), checked once as the file's own values are.

use crate::AppError;
use crate::config::{Config, LoopHead, unused_by_experiment};
use crate::{Context, config};
use mocomp_kin::Model;
use mocomp_sim::HeadMotion;
use std::net::IpAddr;
use std::path::{Path, PathBuf};

/// What the command line sets over the file (`None`, `false`: the file's value, or the
/// default). Each field is the option of the same name.
#[derive(Debug, Clone, Default)]
pub struct DemoOverrides {
    /// `--seconds`.
    pub duration_s: Option<f64>,
    /// `--seed`.
    pub seed: Option<u64>,
    /// `--head-robot`.
    pub head_robot: Option<Model>,
    /// `--head-host`.
    pub head_host: Option<IpAddr>,
    /// `--coil-robot`.
    pub coil_robot: Option<Model>,
    /// `--coil-host`.
    pub coil_host: Option<IpAddr>,
    /// `--paper-period-ms`, s.
    pub paper_period_s: Option<f64>,
    /// `--paper-delay-ms`, s.
    pub paper_delay_s: Option<f64>,
    /// `--contact`.
    pub contact: bool,
    /// `--goal-near`, mm (head frame).
    pub goal_near_mm: Option<[f64; 3]>,
    /// `--loop-head`.
    pub loop_head: Option<LoopHead>,
    /// `--pulses-hz`.
    pub pulses_hz: Option<f64>,
    /// `--record`.
    pub record_mcap: Option<String>,
    /// `--motion-file`.
    pub motion_file: Option<PathBuf>,
    /// `--motion`: a named motion.
    pub motion: Option<String>,
    /// `--speed-mm-s`, m/s.
    pub speed_m_s: Option<f64>,
    /// `--speed-deg-s`, rad/s.
    pub speed_rad_s: Option<f64>,
    /// `--tracker-rate-hz`.
    pub tracker_rate_hz: Option<f64>,
    /// `--tracker-latency-ms`, s.
    pub tracker_latency_s: Option<f64>,
    /// `--tracker-noise-mm`, m.
    pub tracker_noise_m: Option<f64>,
    /// `--tracker-noise-deg`, rad.
    pub tracker_noise_rad: Option<f64>,
    /// `--tracker-dropouts-per-s`.
    pub tracker_dropouts_per_s: Option<f64>,
}

/// The demo's configuration, and what the user should know about it.
#[derive(Debug, Clone)]
pub struct DemoConfig {
    /// Checked.
    pub config: Config,
    /// Notes for the user: keys the experiment does not use, a predictor tuned off the tracker.
    pub notes: Vec<String>,
}

/// The defaults, then `file`, then `o`; checked.
pub fn demo_config(file: Option<&Path>, o: &DemoOverrides) -> Result<DemoConfig, AppError> {
    let mut cfg = Config::default();
    let mut notes = Vec::new();
    let mut unused = Vec::new();
    if let Some(path) = file {
        let text = std::fs::read_to_string(path).what(|| format!("--config {}", path.display()))?;
        cfg = Config::parse(&path.display().to_string(), &text)?;
        unused = unused_by_experiment(&text);
    }
    overlay(&mut cfg, o);
    // A pulsing session's gate is the configuration's.
    if cfg.experiment.pulses_hz.is_some() {
        unused.retain(|k| !k.starts_with("session.gate."));
    }
    if let (Some(path), false) = (file, unused.is_empty()) {
        notes.push(format!(
            "{} sets keys the experiment does not use (it places, calibrates and sets its goal itself): {}",
            path.display(),
            unused.join(", ")
        ));
    }
    motion(&mut cfg.tracker.simulated, o)?;
    cfg.check()?;
    // A scalp file is relative to the configuration's directory.
    let dir = file.and_then(Path::parent).unwrap_or(Path::new(""));
    cfg.load_head(dir)?;
    notes.extend(cfg.head_note());
    notes.extend(cfg.predictor_note());
    Ok(DemoConfig { config: cfg, notes })
}

/// The robots, the paper's pipeline, the tracker model and the recording.
fn overlay(cfg: &mut Config, o: &DemoOverrides) {
    let x = &mut cfg.experiment;
    x.duration_s = o.duration_s.unwrap_or(x.duration_s);
    x.seed = o.seed.or(x.seed);
    x.head_robot = o.head_robot.or(x.head_robot);
    x.head_host = o.head_host.unwrap_or(x.head_host);
    x.paper.period_s = o.paper_period_s.unwrap_or(x.paper.period_s);
    x.paper.compute_delay_s = o.paper_delay_s.unwrap_or(x.paper.compute_delay_s);
    x.contact |= o.contact;
    x.goal_near_mm = o.goal_near_mm.or(x.goal_near_mm);
    x.loop_head = o.loop_head.unwrap_or(x.loop_head);
    x.pulses_hz = o.pulses_hz.or(x.pulses_hz);
    if o.record_mcap.is_some() {
        cfg.record_mcap.clone_from(&o.record_mcap);
    }
    cfg.robot.model = o.coil_robot.unwrap_or(cfg.robot.model);
    if let Some(h) = o.coil_host {
        cfg.robot.host = h.to_string();
    }
    let t = &mut cfg.tracker.simulated.model;
    t.rate_hz = o.tracker_rate_hz.unwrap_or(t.rate_hz);
    t.latency_s = o.tracker_latency_s.unwrap_or(t.latency_s);
    t.noise_m = o.tracker_noise_m.unwrap_or(t.noise_m);
    t.noise_rad = o.tracker_noise_rad.unwrap_or(t.noise_rad);
    t.dropouts_per_s = o.tracker_dropouts_per_s.unwrap_or(t.dropouts_per_s);
}

/// The head's motion: a file, a named motion (a random one takes the tracker's seed, as the
/// run's seed sets both), then its speeds.
fn motion(sim: &mut config::SimTrackerSection, o: &DemoOverrides) -> Result<(), AppError> {
    let opt = |flag: &str, e: String| AppError::Config(format!("--{flag}: {e}"));
    if let Some(file) = &o.motion_file {
        sim.motion = HeadMotion::from_file(&file.to_string_lossy(), Path::new(""))
            .map_err(|e| opt("motion-file", e.to_string()))?;
    }
    if let Some(kind) = &o.motion
        && sim.motion.name() != kind
    {
        sim.motion = HeadMotion::named(kind)
            .ok_or_else(|| opt("motion", format!("{kind:?} is not a motion")))?;
        if let HeadMotion::Random(r) = &mut sim.motion {
            r.seed = sim.model.seed;
        }
    }
    if o.speed_m_s.is_some() || o.speed_rad_s.is_some() {
        sim.motion = sim
            .motion
            .with_speeds(o.speed_m_s, o.speed_rad_s)
            .map_err(|e| {
                let flag = if e.key == "angular_rad_s" {
                    "speed-deg-s"
                } else {
                    "speed-mm-s"
                };
                opt(flag, e.problem.to_string())
            })?;
    }
    Ok(())
}
