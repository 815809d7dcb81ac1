//! `mocomp register`: patient-to-image registration with the calibrated pointer
//! ([`mocomp_app::registration::register`]): the landmarks touched in turn, the scalp swept, the result written
//! with what it is worth; `mocomp register check`: whether the head marker moved on the head
//! since.

use clap::{Args, Subcommand};
use mocomp_app::config::Setup;
use mocomp_app::registration::open::{Opened, Source};
use mocomp_app::registration::register::{Asked, Follow};
use mocomp_app::registration::rehearsal::ask_for;
use mocomp_app::registration::report;
use mocomp_sim::operator::Ask;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

/// Register the patient's head marker to the image: touch the landmarks with the calibrated
/// pointer (each held still, then taken away), then sweep the scalp until the error bound at the
/// targets is small enough; writes the registration (`[head] registration` reads it) only when
/// it passes its checks, with each landmark's error, the FRE, the sweep's fit and the error
/// bound (95 %) at the session's targets; exits 1 naming what to redo otherwise.
#[derive(Debug, Clone, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct RegisterCmd {
    #[command(subcommand)]
    check: Option<RegisterSub>,
    #[command(flatten)]
    live: LiveArgs,
}

#[derive(Debug, Clone, Subcommand)]
enum RegisterSub {
    /// Touch one landmark again: has the head marker moved on the head since registration?
    Check(CheckArgs),
}

/// Where the configuration, the pointer and the streams are.
#[derive(Debug, Clone, Args)]
struct Common {
    /// The configuration: `[head] mesh` (or the ellipsoid) and `[head.landmarks]`,
    /// `[registration]` (and, for `check`, `[head] registration`).
    #[arg(long, value_name = "FILE", required = true)]
    config: Option<PathBuf>,
    /// The pointer's calibration (`mocomp pointer calibrate`; default pointer.toml; with
    /// --simulate, the simulated pointer is calibrated first unless this is given).
    #[arg(long, value_name = "FILE")]
    pointer: Option<PathBuf>,
    /// The OpenIGTLink server streaming the pointer and the head marker.
    #[arg(long, value_name = "HOST:PORT", required_unless_present = "simulate")]
    igtl: Option<String>,
    /// The head marker's device (with --simulate: `[tracker] device`).
    #[arg(long, default_value = "HeadToTracker")]
    head_device: String,
    /// Give up when nothing arrives for this many seconds.
    #[arg(long, default_value_t = 30.0)]
    timeout: f64,
    /// Rehearse in the built-in world: the simulated tracker streams the head marker and a
    /// pointer that a simulated operator (`[tracker.simulated.operator]`) moves as asked; the
    /// report adds the error against the simulation's truth.
    #[arg(long)]
    simulate: bool,
    /// The simulated operator's and tracker's seed (with --simulate).
    #[arg(long, requires = "simulate")]
    seed: Option<u64>,
}

impl Common {
    fn load(&self) -> anyhow::Result<Setup> {
        crate::args::positive("--timeout", self.timeout)?;
        let config = self
            .config
            .as_ref()
            .ok_or_else(|| crate::UsageError("--config: needed".into()))?;
        Ok(Setup::load(config)?)
    }

    fn open(&self, setup: Setup, progress: &mut dyn Write) -> anyhow::Result<Opened> {
        let source = Source {
            rehearse: self.simulate.then_some(self.seed),
            igtl: self.igtl.clone(),
            head_device: self.head_device.clone(),
            pointer: self.pointer.clone(),
            timeout: Duration::from_secs_f64(self.timeout),
        };
        let o = mocomp_app::registration::open::open(setup, &source)?;
        if let Some(said) = &o.said {
            writeln!(progress, "{said}")?;
        }
        Ok(o)
    }
}

#[derive(Debug, Clone, Args)]
struct LiveArgs {
    #[command(flatten)]
    common: Common,
    /// The landmarks to touch, in order (each named in `[head.landmarks]`; default
    /// `[registration] landmarks`).
    #[arg(long, value_delimiter = ',')]
    landmarks: Option<Vec<String>>,
    /// Sweep points at most (0: the landmarks alone; default `[registration] sweep_points`).
    #[arg(long)]
    sweep_points: Option<usize>,
    /// Where to write the registration (only when it passes its checks).
    #[arg(long, value_name = "FILE", default_value = "registration.toml")]
    out: PathBuf,
    /// Print the result as one JSON object.
    #[arg(long)]
    json: bool,
    /// The operator's console: the registration waits for its Start, then shows each step.
    #[command(flatten)]
    dashboard: crate::dashboard::DashboardArgs,
}

#[derive(Debug, Clone, Args)]
struct CheckArgs {
    #[command(flatten)]
    common: Common,
    /// The landmark to touch.
    #[arg(long, default_value = "nasion")]
    landmark: String,
    /// Print the result as one JSON object.
    #[arg(long)]
    json: bool,
}

impl RegisterCmd {
    /// Runs it. Exits 1 when the registration is refused (nothing written), and for `check`
    /// when the marker moved.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        match self.check {
            Some(RegisterSub::Check(c)) => check(c, out),
            None => live(self.live, out),
        }
    }
}

/// The registration's progress on standard error and in the console.
struct Shown<'p, 'c> {
    page: &'p mut mocomp_console::navigation::Page<'c>,
}

impl Follow for Shown<'_, '_> {
    fn say(&mut self, line: &str) {
        eprintln!("{line}");
        self.page.said(line);
    }
    fn moved(&mut self, p: &mocomp_nav::Procedure<'_>) {
        self.page.procedure(p);
    }
}

fn live(a: LiveArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    // With --json, standard output is the result alone: progress goes to stderr.
    let mut stderr = std::io::stderr();
    let progress: &mut dyn Write = if a.json { &mut stderr } else { out };
    let setup = a.common.load()?;
    let section = &setup.file.registration;
    let asked = Asked {
        landmarks: a
            .landmarks
            .clone()
            .unwrap_or_else(|| section.landmarks.clone()),
        sweep_points: a.sweep_points.unwrap_or(section.sweep_points),
    };
    // The image's landmarks on the scalp before a pointer is pivoted or a tip read.
    mocomp_app::registration::register::check_landmarks(&setup, &asked.landmarks)?;
    let o = a.common.open(setup, progress)?;
    let controls = mocomp_app::frontend::Controls::new();
    let console = a.dashboard.start(&o.setup, &controls, progress)?;
    let mut page = mocomp_console::navigation::Page::new(console.as_ref(), "registration");
    if console.is_some() {
        page.wait_for_go(&controls)?;
    }
    let result = mocomp_app::registration::register::register_live(
        &o.setup,
        &o.streams,
        &o.pointer,
        &asked,
        &mut Shown { page: &mut page },
        &mut |p| o.ask(ask_for(p)),
    );
    let r = result.inspect_err(|e| page.failed(&mocomp_app::in_full(e)))?;
    let truth = o.true_errors(&r)?;
    let written = match &r.file {
        Some(file) => {
            mocomp_app::config::registration_file::save(&a.out, file)?;
            Some(a.out.display().to_string())
        }
        None => None,
    };
    let lines = report::lines(&r, truth.as_deref());
    page.registered(&lines, r.usable());
    if a.json {
        let json = report::json(&r, truth.as_deref(), written.as_deref());
        writeln!(out, "{json}")?;
    } else {
        for l in &lines {
            writeln!(out, "{l}")?;
        }
        if let Some(w) = &written {
            writeln!(
                out,
                "written to {w}; set [head] registration = \"{w}\" to use it"
            )?;
        }
    }
    match mocomp_app::registration::register::refused(&r) {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

fn check(c: CheckArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let setup = c.common.load()?;
    let o = c.common.open(setup, &mut std::io::stderr())?;
    o.ask(Ask::Touch(c.landmark.clone()));
    let r = mocomp_app::registration::register::check_live(
        &o.setup,
        &o.streams,
        &o.pointer,
        &c.landmark,
        &mut |s| eprintln!("{s}"),
    )?;
    if c.json {
        writeln!(out, "{}", report::checked_json(&r))?;
    } else {
        writeln!(out, "{r}")?;
    }
    match report::checked_refusal(&r) {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}
