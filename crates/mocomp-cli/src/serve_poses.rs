//! `mocomp serve-poses`: poses served over OpenIGTLink (TRANSFORM messages), from a file or a
//! gently moving head, for trying a set-up without a tracker.

use anyhow::{Context, Result};
use clap::Args;
use mocomp_app::pose_lines::{self, ServeOptions};
use mocomp_geom::matrix_mm_from_iso;
use mocomp_igtl::server::{Server, ServerConfig};
use std::io::Write;
use std::path::Path;

/// Serve poses over OpenIGTLink (TRANSFORM messages) from a file or a simulated head.
#[derive(Debug, Clone, Args)]
pub struct ServePosesCmd {
    /// Port to listen on (PLUS and Slicer use 18944; 0: any free port, printed).
    #[arg(long, default_value_t = 18944)]
    igtl_port: u16,
    /// Address to bind.
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// "sim" (a gently moving head), or a JSON-lines file with "tracker_from_marker" (4×4, mm),
    /// such as `mocomp listen --json` output.
    #[arg(long, value_name = "FILE|sim")]
    from: String,
    /// Device name.
    #[arg(long, default_value = "HeadToTracker")]
    device: String,
    /// Poses per second.
    #[arg(long, default_value_t = 60.0, value_parser = crate::args::rate_hz)]
    rate: f64,
    /// Stop after this many (default: the file once; forever for sim).
    #[arg(long)]
    count: Option<u64>,
    /// Header version: 1, or 2 with TransformStatus metadata (as PLUS and Slicer send).
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=2))]
    header_version: u16,
}

impl ServePosesCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let a = self;
        let file = match a.from.as_str() {
            "sim" => None,
            path => Some(pose_lines::read(Path::new(path))?),
        };
        let server = Server::bind(
            &format!("{}:{}", a.host, a.igtl_port),
            ServerConfig::default(),
        )
        .with_context(|| format!("--igtl-port {}: cannot listen on {}", a.igtl_port, a.host))?;
        writeln!(
            out,
            "serving {:?} on {}; waiting for a client",
            a.device,
            server.local_addr()
        )?;
        out.flush()?;
        let opts = ServeOptions {
            device: a.device,
            rate_hz: a.rate,
            count: a.count,
            header_version: a.header_version,
        };
        let s = pose_lines::serve(&server, file.as_deref(), &opts)?;
        let t = matrix_mm_from_iso(&s.last);
        writeln!(
            out,
            "sent {} poses to {} client(s) ({} dropped as slow); last at ({:.1}, {:.1}, {:.1}) mm",
            s.sent,
            s.clients,
            s.dropped_slow,
            t[(0, 3)],
            t[(1, 3)],
            t[(2, 3)]
        )?;
        Ok(())
    }
}
