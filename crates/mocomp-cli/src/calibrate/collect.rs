//! `mocomp calibrate collect --config FILE`: the calibration collection on the live robot
//! ([`mocomp_app::robot::collect`]) with a progress bar; prints the report and where it was saved.

use crate::dashboard::DashboardArgs;
use clap::Args;
use mocomp_app::config::Setup;
use mocomp_app::frontend::Controls;
use mocomp_app::robot::collect::Progress;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;

/// Collect calibration pairs on the configured robot, solve and save (the arm moves).
///
/// Runs the planned calibration poses on the configured robot, measures the flange's marker with
/// the configured tracker at each (progress bar), solves, and saves the calibration and the pairs.
/// Settings: the configuration's `[calibrate]` section. The arm moves: clear the space.
#[derive(Debug, Clone, Args)]
pub struct CollectCmd {
    /// The configuration (as for `run`).
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Write the calibration here (default: `calibrate.out`, beside the configuration).
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
    /// No progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// The operator's console: the collection waits for its Start (the arm moves only then),
    /// shows its progress, and its Stop (or Ctrl-C) ends it and stops the robot.
    #[command(flatten)]
    pub dashboard: DashboardArgs,
}

impl CollectCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let setup = Setup::load(&self.config)?;
        let controls = Controls::new();
        let console = self.dashboard.start(&setup, &controls, out)?;
        if console.is_some() {
            let controls = Arc::clone(&controls);
            ctrlc::set_handler(move || controls.stop())?;
        }
        let bar = crate::print::bar(
            0,
            "{prefix} [{bar:30}] {pos}/{len} poses, {elapsed} {msg}",
            self.quiet,
        );
        bar.set_prefix("collecting");
        let result = mocomp_app::robot::collect::collect(
            &setup,
            self.out.as_deref(),
            out,
            &mut |p| {
                if let Some(c) = &console {
                    c.calibration_progress(&p);
                }
                if let Some(text) = p.announcement() {
                    // Before the arm moves, whether or not the bar shows (standard output is
                    // `out`, held by this thread: the lock is reentrant and the order kept).
                    bar.suspend(|| println!("{text}"));
                }
                match p {
                    Progress::Planned { poses, .. } => bar.set_length(poses as u64),
                    Progress::Pose { index, seen } => {
                        if !seen {
                            bar.set_message(format!("marker not seen at pose {}", index + 1));
                        }
                        bar.inc(1);
                    }
                    Progress::Waiting { .. } => {}
                }
            },
            console.as_ref().map(|_| controls.as_ref()),
        );
        bar.finish_and_clear();
        if let Some(c) = &console {
            c.calibration_finished(match &result {
                Ok(got) => Ok(got.one_line()),
                Err(e) => Err(mocomp_app::in_full(e)),
            });
        }
        write!(out, "{}", result?.text(&setup))?;
        Ok(())
    }
}
