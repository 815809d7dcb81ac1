//! `mocomp listen`: the poses an OpenIGTLink server streams ([`mocomp_app::listen`]), printed.

use anyhow::Result;
use clap::Args;
use mocomp_app::AppError;
use mocomp_app::listen::{Heard, ListenOptions, listen};
use serde::Serialize;
use std::io::Write;
use std::time::Duration;

#[derive(Serialize)]
struct PoseJson<'a> {
    device: &'a str,
    /// Message timestamp, seconds since the Unix epoch (null when the sender sets none).
    t: Option<f64>,
    valid: bool,
    tracker_from_marker: [[f64; 4]; 4],
}

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
            self.print(out, h)
                .map_err(|e| AppError::failed("writing the poses", e))
        })?;
        eprintln!(
            "{poses} poses; {} messages, {} CRC errors, {} malformed, {} zero timestamps, {} backwards, {} clock steps, {} reconnects",
            c.messages,
            c.crc_errors,
            c.malformed,
            c.zero_timestamps,
            c.backwards_timestamps,
            c.clock_steps,
            c.connections.saturating_sub(1)
        );
        Ok(())
    }

    fn print(&self, out: &mut dyn Write, h: &Heard) -> std::io::Result<()> {
        let m = &h.matrix_mm;
        if self.json {
            let j = PoseJson {
                device: &self.device,
                t: h.t,
                valid: h.valid,
                tracker_from_marker: std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])),
            };
            writeln!(
                out,
                "{}",
                serde_json::to_string(&j).map_err(std::io::Error::other)?
            )?;
        } else {
            writeln!(
                out,
                "{} t={} {} ({:.2}, {:.2}, {:.2}) mm",
                self.device,
                h.t.map_or_else(|| "none".into(), |t| format!("{t:.6}")),
                if h.valid { "valid" } else { "INVALID" },
                m[(0, 3)],
                m[(1, 3)],
                m[(2, 3)]
            )?;
        }
        out.flush()
    }
}
