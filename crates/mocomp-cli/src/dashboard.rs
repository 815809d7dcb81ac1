//! `--dashboard [ADDR]` and its companions, for the commands that can serve the operator's
//! console (`run`, `calibrate collect`): parsed here, started by `mocomp-console`.

use crate::UsageError;
use clap::Args;
use mocomp_app::config::Setup;
use mocomp_app::frontend::Controls;
use mocomp_console::{Console, ConsoleError, ConsoleOptions};
use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;

/// The console's options.
#[derive(Debug, Clone, Args)]
pub struct DashboardArgs {
    /// Serve the operator's console (a web page) on ADDR [default: 127.0.0.1:8080; port 0: any
    /// free port]. Prints one line `dashboard: http://ADDR/?token=TOKEN` at start.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = mocomp_console::DEFAULT_ADDR)]
    pub dashboard: Option<SocketAddr>,
    /// Let the console listen on an address other than loopback (it is then reachable from the
    /// network, and every request needs the token).
    #[arg(long, requires = "dashboard")]
    pub dashboard_allow_remote: bool,
    /// Write the console's token to this file, readable by its owner only (0600).
    #[arg(long, value_name = "FILE", requires = "dashboard")]
    pub dashboard_token_file: Option<PathBuf>,
}

impl DashboardArgs {
    /// Starts the console when asked, and prints its link on `progress`.
    pub fn start(
        &self,
        setup: &Setup,
        controls: &Arc<Controls>,
        progress: &mut dyn Write,
    ) -> anyhow::Result<Option<Console>> {
        let Some(addr) = self.dashboard else {
            return Ok(None);
        };
        let options = ConsoleOptions {
            addr,
            allow_remote: self.dashboard_allow_remote,
            token_file: self.dashboard_token_file.clone(),
        };
        let console =
            Console::start(&options, setup, Arc::clone(controls)).map_err(|e| match e {
                ConsoleError::Remote(_) => UsageError(e.to_string()).into(),
                other => anyhow::Error::new(other),
            })?;
        writeln!(progress, "dashboard: {}", console.url())?;
        progress.flush()?;
        Ok(Some(console))
    }
}
