//! `mocomp listen`: the poses an OpenIGTLink server streams ([`mocomp_app::listen`]), printed.

use anyhow::Result;
use clap::Args;
use mocomp_app::AppError;
use mocomp_app::listen::{ListenOptions, counts_line, listen};
use std::io::Write;
use std::time::Duration;

/// Print the poses an OpenIGTLink server streams (PLUS, 3D Slicer, a tracker), as received.
#[derive(Debug, Clone, Args)]
pub struct ListenCmd {
    /// Server address.
    #[arg(long, value_name = "HOST:PORT")]
    igtl: String,
    /// Device name (TRANSFORM device or TDATA tool), e.g. PLUS's HeadToTracker.
    #[arg(long, default_value = "HeadToTracker")]
    device: String,
    /// Stop after this many poses.
    #[arg(long)]
    count: Option<u64>,
    /// Give up when no pose arrives for this many seconds.
    #[arg(long, default_value_t = 10.0)]
    timeout: f64,
    /// Ask the server for a TDATA stream (STT_TDATA) after connecting.
    #[arg(long)]
    stt_tdata: bool,
    /// One JSON line per pose: {"device", "t", "valid", "tracker_from_marker": [[4×4, mm]]}.
    #[arg(long)]
    json: bool,
}

impl ListenCmd {
    /// Runs it. Exit 1 when no pose arrives within the timeout.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        crate::args::positive("--timeout", self.timeout)?;
        let o = ListenOptions {
            addr: self.igtl.clone(),
            device: self.device.clone(),
            count: self.count,
            timeout: Duration::from_secs_f64(self.timeout),
            stt_tdata: self.stt_tdata,
        };
        let mut poses = 0u64;
        let c = listen(&o, &mut |h| {
            poses += 1;
            let line = if self.json {
                h.json(&self.device)
            } else {
                h.line(&self.device)
            };
            writeln!(out, "{line}")
                .and_then(|()| out.flush())
                .map(|()| std::ops::ControlFlow::Continue(()))
                .map_err(|e| AppError::failed("writing the poses", e))
        })?;
        eprintln!("{}", counts_line(poses, &c));
        Ok(())
    }
}
