//! `mocomp teach-goal --config FILE`: the coil's current pose relative to the head becomes the
//! goal ([`mocomp_app::robot::teach`]), written into the file in place.

use clap::Args;
use mocomp_app::config::Setup;
use std::io::Write;
use std::path::PathBuf;

/// Store the coil's current pose relative to the head as the goal.
///
/// Averages the head marker
/// while the robot holds still, checks the goal against the head model, and writes `[goal]
/// head_from_coil` into the configuration file in place (comments kept).
#[derive(Debug, Clone, Args)]
pub struct TeachCmd {
    /// The configuration (as for `run`).
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Head marker samples to average.
    #[arg(long, default_value_t = 30)]
    pub samples: usize,
    /// Print the goal, do not write it.
    #[arg(long)]
    pub dry_run: bool,
    /// Keep it as the session's target NAME instead (in `[session] targets`, default
    /// `session-targets.toml` beside the configuration), replacing one of that name; the
    /// configuration's goal is left as it is.
    #[arg(long, value_name = "NAME")]
    pub name: Option<String>,
    /// A note kept with the target (with --name).
    #[arg(long, default_value = "", requires = "name")]
    pub note: String,
}

impl TeachCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let setup = Setup::load(&self.config)?;
        let t = mocomp_app::robot::teach::teach(&setup, self.samples, out)?;
        write!(out, "{}", t.text())?;
        if let Some(name) = &self.name {
            let file = mocomp_app::navigation::targets::session_file(&setup);
            if self.dry_run {
                writeln!(out, "--dry-run: {} not changed", file.display())?;
                return Ok(());
            }
            mocomp_app::robot::teach::write_taught(&file, name, &self.note, &t)?;
            writeln!(out, "wrote target {name:?} to {}", file.display())?;
            return Ok(());
        }
        if self.dry_run {
            writeln!(out, "--dry-run: {} not changed", self.config.display())?;
            return Ok(());
        }
        mocomp_app::robot::teach::write_goal(&self.config, &t)?;
        writeln!(out, "wrote the goal to {}", self.config.display())?;
        Ok(())
    }
}
