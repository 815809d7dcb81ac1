//! `mocomp targets list|delete|grid --file FILE`: the session's named targets
//! ([`mocomp_app::targets`]).

use crate::UsageError;
use clap::{Args, Subcommand};
use mocomp_app::config::Setup;
use mocomp_session::GridParams;
use std::io::Write;
use std::path::PathBuf;

/// A session's targets.
#[derive(Debug, Clone, Args)]
pub struct TargetsCmd {
    /// The targets file (TOML; created when a target is first written).
    #[arg(
        long,
        value_name = "FILE",
        global = true,
        default_value = "session-targets.toml"
    )]
    file: PathBuf,
    #[command(subcommand)]
    command: TargetsCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum TargetsCommand {
    /// Print the targets: name, position (mm) and approach axis in the head marker's frame, when
    /// taught, note.
    List {
        /// One JSON object per target instead.
        #[arg(long)]
        json: bool,
    },
    /// Delete a target.
    Delete {
        /// Its name.
        name: String,
    },
    /// Add a grid of targets around one, on the head model's surface, each coil along the
    /// surface normal, named NAME-r<row>c<col>.
    Grid {
        /// The target at the grid's centre.
        name: String,
        /// The configuration whose `[head]` model the grid lies on.
        #[arg(long, value_name = "FILE")]
        config: PathBuf,
        /// Distance between neighbours, mm.
        #[arg(long, value_name = "MM", default_value_t = 10.0)]
        spacing_mm: f64,
        /// Rows (along the target's y).
        #[arg(long, default_value_t = 3)]
        rows: usize,
        /// Columns (along the target's x).
        #[arg(long, default_value_t = 3)]
        cols: usize,
    },
}

impl TargetsCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let mut targets = mocomp_app::targets::load(&self.file)?;
        match self.command {
            TargetsCommand::List { json } => {
                for t in &targets.targets {
                    writeln!(out, "{}", if json { t.json() } else { t.line() })?;
                }
            }
            TargetsCommand::Delete { name } => {
                targets
                    .delete(&name)
                    .map_err(|e| UsageError(e.to_string()))?;
                mocomp_app::targets::save(&self.file, &targets)?;
                writeln!(out, "deleted {name}")?;
            }
            TargetsCommand::Grid {
                name,
                config,
                spacing_mm,
                rows,
                cols,
            } => {
                let setup = Setup::load(&config)?;
                let p = GridParams {
                    spacing_m: spacing_mm * 1e-3,
                    rows,
                    cols,
                };
                let names = mocomp_app::targets::add_grid(&setup, &mut targets, &name, &p)?;
                mocomp_app::targets::save(&self.file, &targets)?;
                writeln!(out, "added {} targets: {}", names.len(), names.join(", "))?;
            }
        }
        Ok(())
    }
}
