//! `mocomp calibrate`: hand-eye and robot-world calibration, X = flange_from_marker and
//! Y = base_from_tracker.

mod collect;
mod plan;
mod solve;
mod synth;

use anyhow::Result;
use clap::{Args, Subcommand};
use mocomp_calib::NoiseModel;
use std::io::Write;

/// Hand-eye and robot-world calibration: X = flange_from_marker, Y = base_from_tracker.
#[derive(Debug, Clone, Args)]
pub struct CalibrateCmd {
    #[command(subcommand)]
    command: CalibrateCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum CalibrateCommand {
    Collect(collect::CollectCmd),
    Solve(solve::SolveCmd),
    Plan(plan::PlanCmd),
    Synth(synth::SynthCmd),
}

impl CalibrateCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        match self.command {
            CalibrateCommand::Collect(c) => c.run(out),
            CalibrateCommand::Solve(c) => c.run(out),
            CalibrateCommand::Plan(c) => c.run(out),
            CalibrateCommand::Synth(c) => c.run(out),
        }
    }
}

/// Noise levels given as (mm, degrees) for the tracker and the robot.
fn noise(tracker: [f64; 2], robot: [f64; 2]) -> NoiseModel {
    NoiseModel::from_mm_deg(tracker[0], tracker[1], robot[0], robot[1])
}
