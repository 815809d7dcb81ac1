//! `mocomp demo`: the paper's two-robot experiment on the simulated world
//! ([`mocomp_app::experiment`]), both controllers on the same trajectory, with a progress bar;
//! writes its record ([`mocomp_report::demo`]) and prints the summary.
//!
//! Settings come from the defaults, then `--config FILE` (the one configuration, see
//! [`mocomp_app::config`]; the experiment reads the keys [`mocomp_app::config::ExperimentSection`]
//! lists), then the command-line options; `--print-config` prints the result as a file instead
//! of running.

use crate::dashboard::DashboardArgs;
use anyhow::Context;
use clap::Args;
use mocomp_app::AppError;
use mocomp_app::config::Config;
use mocomp_app::config::Setup;
use mocomp_app::demo::options::{DemoOverrides, demo_config};
use mocomp_app::demo::run::DemoFront;
use mocomp_app::experiment::Controller;
use mocomp_app::frontend::Controls;
use mocomp_geom::units::{deg_to_rad, mm_to_m};
use mocomp_kin::Model;
use std::io::Write;
use std::net::IpAddr;
use std::path::PathBuf;
use std::sync::Arc;

/// The paper's two-robot experiment on the simulated world: `paper` and `mocomp` compared.
///
/// A UR5 moves a head phantom, a UR3
/// compensates, tracker over OpenIGTLink, both robots calibrated first): the `paper` pipeline
/// and `mocomp` on the same trajectory; writes demo.csv, the figures (PNG and SVG), summary.md
/// and config.toml. Unset options keep the configuration file's value, or the default.
#[derive(Debug, Clone, Args)]
pub struct DemoCmd {
    /// The configuration (TOML, the same file as `run`'s; `--print-config` prints it with
    /// every key).
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print the configuration as a file (defaults, the file and the options applied) and exit:
    /// `mocomp run --config` runs it too.
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
    /// The operator's console: each controller's run is paced in real time (the record is the
    /// same), its status shows in the page, and its hold (mocomp's run) and stop reach it.
    #[command(flatten)]
    pub dashboard: DashboardArgs,
    /// The controllers to run, in this order: `paper` (the original pipeline), `mocomp`, and
    /// `oracle` (mocomp's loop knowing the head's true future with no latency, on the same robot:
    /// the least error any controller could make; the summary gives the others' excess over it)
    /// [paper,mocomp].
    #[arg(long, value_delimiter = ',', value_parser = crate::args::controller, value_name = "NAMES")]
    pub controllers: Option<Vec<Controller>>,
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
    /// Record both runs to this MCAP file (overrides `record_mcap`): the topics `mocomp run
    /// --record` records and every cycle record, naming its controller, one run after the
    /// other on the experiment's clock (Foxglove, `ros2 bag`).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<String>,
    /// On the scalp: the goal moved along the coil's axis until it touches; mocomp holds
    /// `loop.contact_force_n` (3 N) by its admittance, the paper's controller holds the pose.
    #[arg(long)]
    pub contact: bool,
    /// The goal over the scalp point nearest this point (head marker's frame, mm), 3 mm off
    /// along its normal (overrides `experiment.goal_near_mm`; default: on top of the head).
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::args::three, allow_hyphen_values = true)]
    pub goal_near: Option<[f64; 3]>,
    /// The goal is this session target (`mocomp targets add`, `teach-goal --name`) instead:
    /// from `--targets`, else the configuration's `[session] targets`.
    #[arg(long, value_name = "NAME", conflicts_with = "goal_near")]
    pub target: Option<String>,
    /// The targets file `--target` is in.
    #[arg(long, value_name = "FILE", requires = "target")]
    pub targets: Option<PathBuf>,
    /// The head model the controllers believe: "head", or "fitted-ellipsoid" (the ellipsoid
    /// fitted to `head.mesh`, while the phantom stays the mesh: what an ellipsoid lets through).
    #[arg(long, value_name = "head|fitted-ellipsoid", value_parser = mocomp_app::config::LoopHead::parse)]
    pub loop_head: Option<mocomp_app::config::LoopHead>,
    /// A stimulator trying a pulse through the gate (`[session.gate]`) this many times a second
    /// during each mocomp run (overrides `experiment.pulses_hz`); the summary scores the pulses
    /// against the goal and, with `[coil] model`, in dose.
    #[arg(long, value_name = "HZ")]
    pub pulses_hz: Option<f64>,
    /// Bump the simulated tracker this many seconds into each run (the camera knocked: the
    /// calibration no longer holds); the summary says how soon the drift monitor saw it.
    #[arg(long, value_name = "S")]
    pub tracker_bump_at_s: Option<f64>,
    /// The bump's shift along the camera's x axis, mm [3].
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 3.0,
        requires = "tracker_bump_at_s"
    )]
    pub tracker_bump_mm: f64,
    /// The bump's turn about the camera's z axis, degrees [1].
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 1.0,
        requires = "tracker_bump_at_s"
    )]
    pub tracker_bump_deg: f64,
}

impl DemoCmd {
    /// The configuration: defaults, then the file, then the options (converted to SI here,
    /// at the edge).
    fn configuration(&self) -> anyhow::Result<Config> {
        let overrides = DemoOverrides {
            duration_s: self.seconds,
            seed: self.seed,
            head_robot: self.head_robot,
            head_host: self.head_host,
            coil_robot: self.coil_robot,
            coil_host: self.coil_host,
            paper_period_s: self.paper_period_ms.map(|v| v * 1e-3),
            paper_delay_s: self.paper_delay_ms.map(|v| v * 1e-3),
            contact: self.contact,
            goal_near_mm: self.goal_near,
            loop_head: self.loop_head,
            pulses_hz: self.pulses_hz,
            record_mcap: self.record.clone(),
            motion_file: self.motion_file.clone(),
            motion: self.motion.clone(),
            speed_m_s: self.speed_mm_s.map(mm_to_m),
            speed_rad_s: self.speed_deg_s.map(deg_to_rad),
            tracker_rate_hz: self.tracker_rate_hz,
            tracker_latency_s: self.tracker_latency_ms.map(|v| v * 1e-3),
            tracker_noise_m: self.tracker_noise_mm.map(mm_to_m),
            tracker_noise_rad: self.tracker_noise_deg.map(deg_to_rad),
            tracker_dropouts_per_s: self.tracker_dropouts_per_s,
        };
        let c = demo_config(self.config.as_deref(), &overrides)?;
        for note in &c.notes {
            eprintln!("note: {note}");
        }
        Ok(c.config)
    }

    /// The controllers to run, each once.
    fn order(&self) -> Result<Vec<Controller>, crate::UsageError> {
        let order = self
            .controllers
            .clone()
            .unwrap_or_else(|| vec![Controller::Paper, Controller::Mocomp]);
        if order.is_empty() {
            return Err(crate::UsageError("--controllers: none named".into()));
        }
        for (i, c) in order.iter().enumerate() {
            if order[..i].contains(c) {
                return Err(crate::UsageError(format!(
                    "--controllers: {} named twice",
                    c.name()
                )));
            }
        }
        Ok(order)
    }

    /// Runs the demo (or prints its configuration).
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let config = self.configuration()?;
        let mut exp = mocomp_app::demo::experiment_config::from_config(&config)?;
        if let Some(name) = &self.target {
            let dir = self
                .config
                .as_deref()
                .and_then(std::path::Path::parent)
                .map(std::path::Path::to_path_buf)
                .unwrap_or_default();
            exp.coil_design = mocomp_app::navigation::targets::goal_named(
                &config,
                &dir,
                name,
                self.targets.as_deref(),
            )?;
            exp.validate()
                .map_err(|e| crate::UsageError(format!("--target {name}: {e}")))?;
        }
        if let Some(at) = self.tracker_bump_at_s {
            exp.bump_tracker(
                at,
                mm_to_m(self.tracker_bump_mm),
                deg_to_rad(self.tracker_bump_deg),
            )
            .map_err(|e| crate::UsageError(e.to_string()))?;
        }
        let order = self.order()?;
        let file = mocomp_app::config::template::print(&config)?;
        if self.print_config {
            write!(out, "{file}")?;
            return Ok(());
        }
        std::fs::create_dir_all(&self.out)
            .with_context(|| format!("--out {}", self.out.display()))?;
        let bar = crate::print::bar(
            1000,
            "{prefix:>28} [{bar:30}] {percent:>3}% {elapsed}",
            self.quiet,
        );
        let controls = Controls::new();
        let setup = Setup::new(config.clone(), None, PathBuf::new())?;
        let console = self.dashboard.start(&setup, &controls, out)?;
        if console.is_some() {
            let controls = Arc::clone(&controls);
            ctrlc::set_handler(move || controls.stop())?;
        }
        let run = mocomp_app::demo::run::run(
            &config,
            &exp,
            &order,
            console.as_ref().map(|c| c as &dyn DemoFront),
            &controls,
            &mut |name, f| {
                bar.set_prefix(name.to_string());
                bar.set_position((f * 1000.0) as u64);
            },
        )?;
        let record = run.record;
        let outcome = run.outcome?;
        bar.finish_and_clear();
        if controls.stop_requested() {
            return Err(AppError::Refused(
                "stopped by the operator before the experiment ended: no record written".into(),
            )
            .into());
        }
        // The configuration it ran with goes beside the record: `--config` with it repeats the run.
        let w = mocomp_report::demo::write(&outcome, &exp, &file, &self.out)?;
        if self.json {
            let mut v = serde_json::to_value(&w.summary)?;
            if let (Some(r), Some(o)) = (&record, v.as_object_mut()) {
                o.insert("record".into(), serde_json::to_value(r)?);
            }
            writeln!(out, "{v}")?;
        } else {
            write!(out, "{}", w.markdown)?;
            writeln!(out, "\n{}", w.files_line(&self.out))?;
            if let Some(r) = &record {
                writeln!(out, "recorded {} messages to {}", r.messages, r.path)?;
            }
        }
        if let Some(e) = record.and_then(|r| r.error.map(|e| (r.path, e))) {
            anyhow::bail!("the recording {} is incomplete: {}", e.0, e.1);
        }
        Ok(())
    }
}
