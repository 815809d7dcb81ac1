//! `mocomp placement check|search --config FILE`: whether the arm reaches a session's targets
//! with the head where it is configured, and where the head should sit for it to reach them all
//! ([`mocomp_app::navigation::placement`]).

use clap::{Args, Subcommand};
use mocomp_app::config::Setup;
use mocomp_app::navigation::placement::{Region, TargetReach, Targets};
use mocomp_app::navigation::placement_report as report;
use mocomp_geom::nalgebra::Isometry3;
use std::io::Write;
use std::path::PathBuf;

/// Whether the arm reaches the session's targets, and where the head should sit for it to.
#[derive(Debug, Clone, Args)]
pub struct PlacementCmd {
    #[command(subcommand)]
    command: PlacementCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum PlacementCommand {
    /// Each target at the configured placement (`tracker.simulated.base_from_head`, the head
    /// in the robot's base frame): the way the loop would take from where the arm rests, the
    /// arm at the target (branch, joint margin, singularity margin), the head's room to move.
    /// Exit 1 when one is not reachable.
    Check(Which),
    /// The placement in a region about the configured one that reaches every target with the
    /// most margin: printed as the configuration's key. Exit 1 when none does.
    Search(SearchCmd),
}

/// The configuration and its targets.
#[derive(Debug, Clone, Args)]
struct Which {
    /// The configuration (its `[head]`, `[goal]`, robot and placement).
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// The targets file (default: `[session] targets`; without either, the `[goal]`).
    #[arg(long, value_name = "FILE")]
    targets: Option<PathBuf>,
    /// Only this target (repeatable).
    #[arg(long, value_name = "NAME")]
    target: Vec<String>,
    /// One JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// Draw the placement from above into this PNG: the robot's base and reach, the head (as
    /// configured, and where the search puts it), each target marked reached or not.
    #[arg(long, value_name = "FILE.png")]
    png: Option<PathBuf>,
}

#[derive(Debug, Clone, Args)]
struct SearchCmd {
    #[command(flatten)]
    which: Which,
    /// Half the box searched about the configured place along the base's x, y, z, mm.
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::args::three, default_value = "200,200,100")]
    region_mm: [f64; 3],
    /// The grid's step, mm.
    #[arg(long, value_name = "MM", default_value_t = 50.0)]
    step_mm: f64,
    /// Turns about the vertical tried each way, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 90.0)]
    yaw_deg: f64,
    /// Their step, degrees.
    #[arg(long, value_name = "DEG", default_value_t = 15.0)]
    yaw_step_deg: f64,
}

impl Which {
    fn load(&self) -> anyhow::Result<(Setup, Goals, Targets)> {
        let setup = Setup::load(&self.config)?;
        let goals = mocomp_app::navigation::placement::goals(
            &setup,
            self.targets.as_deref(),
            &self.target,
        )?;
        let targets = Targets::new(&setup, &goals)?;
        Ok((setup, goals, targets))
    }

    fn draw(
        &self,
        setup: &Setup,
        goals: &Goals,
        configured: (&Isometry3<f64>, &[TargetReach]),
        found: Option<(&Isometry3<f64>, &[TargetReach])>,
        out: &mut dyn Write,
    ) -> anyhow::Result<()> {
        let Some(path) = &self.png else {
            return Ok(());
        };
        let view = mocomp_app::navigation::placement::view(setup, goals, configured, found)?;
        let png = mocomp_report::placement::png(&view)?;
        std::fs::write(path, png).map_err(|e| anyhow::anyhow!("--png {}: {e}", path.display()))?;
        if !self.json {
            writeln!(out, "drew the placement into {}", path.display())?;
        }
        Ok(())
    }
}

type Goals = Vec<(String, Isometry3<f64>)>;

impl PlacementCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        match self.command {
            PlacementCommand::Check(w) => check(&w, out),
            PlacementCommand::Search(s) => search(&s, out),
        }
    }
}

fn check(w: &Which, out: &mut dyn Write) -> anyhow::Result<()> {
    let (setup, goals, targets) = w.load()?;
    let c = targets.at_configured(&setup)?;
    w.draw(&setup, &goals, (&c.place, &c.reaches), None, out)?;
    if w.json {
        writeln!(out, "{}", report::configured_json(&c))?;
    } else {
        for r in &c.reaches {
            writeln!(out, "{r}")?;
        }
    }
    match report::configured_refusal(&c, &w.config) {
        Some(e) => Err(e.into()),
        None => Ok(()),
    }
}

fn search(s: &SearchCmd, out: &mut dyn Write) -> anyhow::Result<()> {
    let (setup, goals, targets) = s.which.load()?;
    let region = Region {
        half_m: s.region_mm.map(|v| v * 1e-3),
        step_m: s.step_mm * 1e-3,
        yaw_half_rad: s.yaw_deg.to_radians(),
        yaw_step_rad: s.yaw_step_deg.to_radians(),
    };
    region
        .check()
        .map_err(|e| crate::UsageError(e.to_string()))?;
    let centre = setup.file.tracker.simulated.base_from_head.iso();
    let found = mocomp_app::navigation::placement::search(&targets, &centre, &region, |p| {
        setup.initial_joints_at(p).ok()
    });
    let searched = report::Searched::new(&found, &centre, &region)?;
    let configured = targets.at_configured(&setup)?;
    s.which.draw(
        &setup,
        &goals,
        (&configured.place, &configured.reaches),
        Some((searched.place(), searched.reaches())),
        out,
    )?;
    if s.which.json {
        writeln!(out, "{}", searched.json())?;
    } else {
        write!(out, "{searched}")?;
    }
    Ok(())
}
