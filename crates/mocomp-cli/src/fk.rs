//! `mocomp fk`: forward kinematics, printed.

use crate::args::ArmArgs;
use anyhow::Result;
use clap::Args;
use mocomp_kin::report::FkReport;
use std::io::Write;

/// Forward kinematics: base_from_flange of a joint configuration (metres, radians).
#[derive(Debug, Clone, Args)]
pub struct FkCmd {
    #[command(flatten)]
    arm: ArmArgs,
    /// Joint angles, radians, base to wrist 3.
    #[arg(long, value_name = "Q1,...,Q6", value_parser = crate::args::six, allow_hyphen_values = true)]
    joints: [f64; 6],
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

impl FkCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let r = FkReport::new(&self.arm.build()?, &self.joints, self.arm.tool.is_some());
        crate::print::report(out, &r, self.json)
    }
}
