//! `mocomp robot`: mocomp's client against a UR controller (a real one, or `mocomp ursim`).

mod state;
mod stream;

use anyhow::Result;
use clap::{Args, Subcommand};
use std::io::Write;

/// Talk to a UR controller (a real one, or `mocomp ursim`) with mocomp's client.
#[derive(Debug, Clone, Args)]
pub struct RobotCmd {
    #[command(subcommand)]
    command: RobotCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum RobotCommand {
    State(state::StateCmd),
    Stream(stream::StreamCmd),
}

impl RobotCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        match self.command {
            RobotCommand::State(c) => c.run(out),
            RobotCommand::Stream(c) => c.run(out),
        }
    }
}
