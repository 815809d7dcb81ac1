//! `mocomp robot state`: mocomp's client against a UR controller, and what it reports.

use anyhow::Result;
use clap::Args;
use mocomp_app::robot::servo_check::StateReport;
use mocomp_kin::Model;
use std::io::Write;
use std::net::IpAddr;

/// Connect, start the control program and print the state.
#[derive(Debug, Clone, Args)]
pub struct StateCmd {
    /// Controller address.
    #[arg(long)]
    host: IpAddr,
    /// Start a simulated controller of this model at --host first.
    #[arg(long, value_parser = crate::args::model)]
    ursim: Option<Model>,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

impl StateCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let _sim = self
            .ursim
            .map(|m| crate::ursim::start(m, self.host, &Default::default()))
            .transpose()?;
        crate::print::report(out, &StateReport::read(self.host)?, self.json)
    }
}
