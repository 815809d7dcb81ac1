//! `mocomp placement check|search --config FILE`: whether the arm reaches a session's targets
//! with the head where it is configured, and where the head should sit for it to reach them all
//! ([`mocomp_app::placement`]).

use clap::{Args, Subcommand};
use mocomp_app::config::Setup;
use mocomp_app::placement::{Region, TargetReach, Targets, pose_vector};
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

fn json_of(reaches: &[TargetReach]) -> serde_json::Value {
    use mocomp_control::compensator::reach::Way;
    reaches
        .iter()
        .map(|r| {
            let at = r.reach.at_goal.map(|g| {
                serde_json::json!({
                    "branch": g.branch.to_string(),
                    "joints_rad": g.joints,
                    "joint_margin_deg": g.joint_margin_rad.to_degrees(),
                    "singularity_margin": g.singularity_margin,
                    "headroom_followed": g.headroom_ok,
                    "headroom_singularity_margin": g.headroom_singularity_margin,
                })
            });
            serde_json::json!({
                "name": r.name,
                "reachable": r.refusal.is_none(),
                "refusal": r.refusal.map(|x| x.to_string()),
                "refusal_code": r.refusal.map(|x| format!("{x:?}")),
                "way": match r.reach.way {
                    Ok(Way::Shell) => "shell".to_string(),
                    Ok(Way::Transit(_)) => "transit".to_string(),
                    Err(_) => "none".to_string(),
                },
                "at_goal": at,
            })
        })
        .collect()
}

impl Which {
    fn load(&self) -> anyhow::Result<(Setup, Goals, Targets)> {
        let setup = Setup::load(&self.config)?;
        let goals = mocomp_app::placement::goals(&setup, self.targets.as_deref(), &self.target)?;
        let targets = Targets::new(&setup, &goals)?;
        Ok((setup, goals, targets))
    }

    /// Draws the placements when `--png` asks.
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
        let view = mocomp_app::placement::view(setup, goals, configured, found)?;
        let png = mocomp_report::placement::png(&view)?;
        std::fs::write(path, png).map_err(|e| anyhow::anyhow!("--png {}: {e}", path.display()))?;
        if !self.json {
            writeln!(out, "drew the placement into {}", path.display())?;
        }
        Ok(())
    }
}

/// The targets' names and goals.
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
    let mocomp_app::placement::Configured {
        place,
        rest,
        reaches,
    } = targets.at_configured(&setup)?;
    let refused = reaches.iter().filter(|r| r.refusal.is_some()).count();
    w.draw(&setup, &goals, (&place, &reaches), None, out)?;
    if w.json {
        writeln!(
            out,
            "{}",
            serde_json::json!({
                "base_from_head": pose_vector(&place),
                "rest_joints_rad": rest,
                "targets": json_of(&reaches),
            })
        )?;
    } else {
        for r in &reaches {
            writeln!(out, "{r}")?;
        }
    }
    if refused > 0 {
        anyhow::bail!(
            "{refused} of {} targets not reachable with the head at \
             tracker.simulated.base_from_head = {}: `mocomp placement search --config {}` finds \
             a place",
            reaches.len(),
            fmt_pose(&place),
            w.config.display()
        );
    }
    Ok(())
}

fn fmt_pose(p: &Isometry3<f64>) -> String {
    let v = pose_vector(p);
    format!(
        "[{:.3}, {:.3}, {:.3}, {:.4}, {:.4}, {:.4}]",
        v[0], v[1], v[2], v[3], v[4], v[5]
    )
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
    let found = mocomp_app::placement::search(&targets, &centre, &region, |p| {
        setup.initial_joints_at(p).ok()
    });
    let Some((place, score, reaches)) = &found.best else {
        anyhow::bail!(
            "none of {} placements within ±{:.0}, ±{:.0}, ±{:.0} mm and ±{:.0}° of the configured \
             one reaches every target: a larger --region-mm or --yaw-deg, or fewer targets",
            found.tried,
            s.region_mm[0],
            s.region_mm[1],
            s.region_mm[2],
            s.yaw_deg
        );
    };
    let configured = targets.at_configured(&setup)?;
    s.which.draw(
        &setup,
        &goals,
        (&configured.place, &configured.reaches),
        Some((place, reaches)),
        out,
    )?;
    let shift = (place.translation.vector - centre.translation.vector) * 1e3;
    let turn = (place.rotation * centre.rotation.inverse())
        .euler_angles()
        .2;
    if s.which.json {
        writeln!(
            out,
            "{}",
            serde_json::json!({
                "tried": found.tried,
                "reaching": found.reaching,
                "score": score,
                "base_from_head": pose_vector(place),
                "moved_mm": [shift.x, shift.y, shift.z],
                "turned_deg": turn.to_degrees(),
                "targets": json_of(reaches),
            })
        )?;
        return Ok(());
    }
    writeln!(
        out,
        "{} placements tried, {} reach every target; the most margin ({score:.2}) with the head \
         moved ({:.0}, {:.0}, {:.0}) mm in the robot's base frame and turned {:.0}° about the \
         vertical:",
        found.tried,
        found.reaching,
        shift.x,
        shift.y,
        shift.z,
        turn.to_degrees()
    )?;
    writeln!(out, "[tracker.simulated]")?;
    writeln!(out, "base_from_head = {}", fmt_pose(place))?;
    for r in reaches {
        writeln!(out, "  {r}")?;
    }
    Ok(())
}
