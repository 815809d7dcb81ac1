//! `mocomp models`: the model table.

use anyhow::Result;
use clap::Args;
use mocomp_kin::report::ModelTable;
use std::io::Write;

/// The model table: DH parameters, maximum joint speeds, control periods.
#[derive(Debug, Clone, Args)]
pub struct ModelsCmd {
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

impl ModelsCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        crate::print::report(out, &ModelTable::all(), self.json)
    }
}
