//! `mocomp config print [--config FILE]`, `mocomp config check FILE` and `mocomp config
//! reference`: the one configuration ([`mocomp_app::config`]) as an effective file with
//! comments, checked, or as the book's reference.

use clap::{Args, Subcommand};
use mocomp_app::config::Setup;
use std::io::Write;
use std::path::PathBuf;

/// The configuration every `--config` takes (`run`, `demo`, `teach-goal`, `calibrate collect`).
#[derive(Debug, Clone, Args)]
pub struct ConfigCmd {
    #[command(subcommand)]
    command: ConfigCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum ConfigCommand {
    /// Print the effective configuration (every key, the defaults with what the file sets) as a
    /// file with comments.
    Print {
        /// The configuration (default: none, i.e. every default).
        #[arg(long, value_name = "FILE")]
        config: Option<PathBuf>,
    },
    /// Check a configuration: every key and value, and what a session needs from it (the
    /// calibration, the coil's mounting, the goal of a real setup). Prints "ok" or the error
    /// naming the key (exit 2).
    Check {
        /// The configuration.
        file: PathBuf,
    },
    /// Print the reference of every key (Markdown: section, key, default, meaning), as the
    /// book's configuration page.
    Reference,
}

impl ConfigCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        match self.command {
            ConfigCommand::Print { config } => {
                let cfg = match config {
                    Some(path) => Setup::load(&path)?.file,
                    None => mocomp_app::config::Config::default(),
                };
                write!(out, "{}", mocomp_app::config::template::print(&cfg)?)?;
            }
            ConfigCommand::Reference => {
                write!(out, "{}", mocomp_app::config::reference::markdown()?)?;
            }
            ConfigCommand::Check { file } => {
                let setup = Setup::load(&file)?;
                // What `run` needs besides: the goal.
                setup.loop_config()?;
                writeln!(
                    out,
                    "{}: ok ({} {}, tracker {})",
                    file.display(),
                    if setup.file.robot.simulate {
                        "simulated"
                    } else {
                        "robot"
                    },
                    setup.model,
                    setup.file.tracker.source
                )?;
                for note in mocomp_app::live::session_wiring::notes(&setup.file) {
                    writeln!(out, "note: {note}")?;
                }
            }
        }
        Ok(())
    }
}
