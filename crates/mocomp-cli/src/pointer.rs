//! `mocomp pointer calibrate`: a tracked pointer's tip from pivoting it on a divot, its poses
//! streamed over OpenIGTLink ([`mocomp_app::registration::pointer`]), written to a file.

use clap::{Args, Subcommand};
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

/// A tracked pointer (stylus).
#[derive(Debug, Clone, Args)]
pub struct PointerCmd {
    #[command(subcommand)]
    command: PointerCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum PointerCommand {
    Calibrate(CalibrateCmd),
}

/// Pivot the pointer's tip in a divot, turning it at least 15° every way, while this collects its
/// poses; writes the tip in the marker's frame and how well the samples agree.
#[derive(Debug, Clone, Args)]
pub struct CalibrateCmd {
    /// The OpenIGTLink server (PLUS, Slicer, the tracker).
    #[arg(long, value_name = "HOST:PORT")]
    igtl: String,
    /// The pointer's TRANSFORM device or TDATA tool.
    #[arg(long, default_value = "StylusToTracker")]
    device: String,
    /// How many valid poses to collect.
    #[arg(long, default_value_t = 200)]
    samples: usize,
    /// Give up when no pose arrives for this many seconds.
    #[arg(long, default_value_t = 10.0)]
    timeout: f64,
    /// Where to write the calibration.
    #[arg(long, value_name = "FILE", default_value = "pointer.toml")]
    out: PathBuf,
    /// Print the calibration as one JSON object.
    #[arg(long)]
    json: bool,
    /// The operator's console: the calibration waits for its Start, then shows the count.
    #[command(flatten)]
    dashboard: crate::dashboard::DashboardArgs,
}

impl PointerCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let PointerCommand::Calibrate(c) = self.command;
        crate::args::positive("--timeout", c.timeout)?;
        if c.samples < mocomp_nav::pivot::MIN_SAMPLES {
            return Err(crate::UsageError(format!(
                "--samples {}: a pivot calibration needs at least {}",
                c.samples,
                mocomp_nav::pivot::MIN_SAMPLES
            ))
            .into());
        }
        let controls = mocomp_app::frontend::Controls::new();
        let setup = mocomp_app::config::Setup::new(
            mocomp_app::config::Config::default(),
            None,
            PathBuf::new(),
        )?;
        let mut stderr = std::io::stderr();
        let progress: &mut dyn Write = if c.json { &mut stderr } else { out };
        let console = c.dashboard.start(&setup, &controls, progress)?;
        let mut page = mocomp_console::navigation::Page::new(console.as_ref(), "pivot");
        if console.is_some() {
            page.wait_for_go(&controls)?;
        }
        eprintln!(
            "pivot the tip of {} in a divot, turning it every way, until {} poses are in",
            c.device, c.samples
        );
        let calibrated = mocomp_app::registration::pointer::collect(
            &c.igtl,
            &c.device,
            c.samples,
            Duration::from_secs_f64(c.timeout),
            &mut |n| page.samples(n, c.samples),
        )
        .and_then(|(poses, invalid)| {
            mocomp_app::registration::pointer::calibrate(&c.device, &poses, invalid)
        });
        let p = calibrated.inspect_err(|e| page.failed(&mocomp_app::in_full(e)))?;
        page.pivoted(&p);
        mocomp_app::registration::pointer::save(&c.out, &p)?;
        if c.json {
            writeln!(out, "{}", serde_json::to_string(&p)?)?;
        } else {
            writeln!(out, "{p}; written to {}", c.out.display())?;
        }
        Ok(())
    }
}
