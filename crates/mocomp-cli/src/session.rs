//! `mocomp session export --config FILE (--bids DIR | --localite FILE.xml)` and `session report
//! --config FILE --out FILE.html`: a session's pulse log for a lab's tools and its files
//! ([`mocomp_app::session_export`]).

use clap::{Args, Subcommand};
use mocomp_app::session_export::{BidsOptions, ExportSource, Exported};
use std::io::Write;
use std::path::PathBuf;

/// A session's record, for other tools.
#[derive(Debug, Clone, Args)]
pub struct SessionCmd {
    #[command(subcommand)]
    command: SessionCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum SessionCommand {
    /// The pulse log (`[session] pulse_log`) as a NIBS-BIDS dataset (BEP037 draft: one row per
    /// pulse in `nibs/*_nibs.tsv`, the coil's pose in `*_markers.tsv`, with the T1 the poses
    /// are in) or as a Localite trigger-marker file (`TriggerMarkers_Coil0_*.xml`).
    Export(ExportCmd),
    /// The session's report: one HTML page (figures inline) with when it ran, the
    /// registration, each target's pulses and errors, and every pulse.
    Report(ReportCmd),
}

#[derive(Debug, Clone, Args)]
struct ReportCmd {
    /// The session's configuration.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// The pulse log (default: the configuration's `[session] pulse_log`).
    #[arg(long, value_name = "FILE")]
    log: Option<PathBuf>,
    /// The report's file.
    #[arg(long, value_name = "FILE.html")]
    out: PathBuf,
}

#[derive(Debug, Clone, Args)]
#[command(group(clap::ArgGroup::new("to").required(true).args(["bids", "localite"])))]
struct ExportCmd {
    /// The session's configuration.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// The pulse log (default: the configuration's `[session] pulse_log`).
    #[arg(long, value_name = "FILE")]
    log: Option<PathBuf>,
    /// Write a BIDS dataset into this folder.
    #[arg(long, value_name = "DIR")]
    bids: Option<PathBuf>,
    /// Write a Localite trigger-marker file.
    #[arg(long, value_name = "FILE.xml")]
    localite: Option<PathBuf>,
    /// The subject's BIDS label.
    #[arg(long, value_name = "LABEL", default_value = "01")]
    subject: String,
    /// The session's BIDS label.
    #[arg(long, value_name = "LABEL", default_value = "01")]
    session: String,
    /// The task's BIDS label.
    #[arg(long, value_name = "LABEL", default_value = "tms")]
    task: String,
    /// The T1 the poses are in, copied into the dataset (default: `[head] mesh` when it is a
    /// NIfTI).
    #[arg(long, value_name = "FILE")]
    t1: Option<PathBuf>,
}

impl SessionCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        match self.command {
            SessionCommand::Export(e) => e.run(out),
            SessionCommand::Report(r) => {
                let source = ExportSource::load(&r.config, r.log.as_deref())?;
                let done = mocomp_app::session_export::report(&source, &r.out, &r.config)?;
                said(out, &source, &done)
            }
        }
    }
}

impl ExportCmd {
    fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let source = ExportSource::load(&self.config, self.log.as_deref())?;
        let done: Exported = match (&self.bids, &self.localite) {
            (Some(dir), _) => mocomp_app::session_export::bids(
                &source,
                dir,
                &BidsOptions {
                    subject: self.subject.clone(),
                    session: self.session.clone(),
                    task: self.task.clone(),
                    t1: self.t1.clone(),
                },
            )?,
            (None, Some(file)) => mocomp_app::session_export::localite(&source, file)?,
            // clap's group asks for one; should it not, the same usage error.
            (None, None) => {
                return Err(
                    crate::UsageError("give --bids DIR or --localite FILE.xml".into()).into(),
                );
            }
        };
        said(out, &source, &done)
    }
}

/// What was written, from which log.
fn said(out: &mut dyn Write, source: &ExportSource, done: &Exported) -> anyhow::Result<()> {
    writeln!(
        out,
        "{} pulses ({} with the coil's pose) from {}:",
        done.pulses,
        done.with_pose,
        source.log.display()
    )?;
    for f in &done.files {
        writeln!(out, "  {}", f.display())?;
    }
    Ok(())
}
