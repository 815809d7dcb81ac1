//! `mocomp serve-poses`: poses served over OpenIGTLink (TRANSFORM messages), from a file or a
//! gently moving head, for trying a set-up without a tracker.

use anyhow::{Context, Result};
use clap::Args;
use mocomp_app::pose_lines;
use mocomp_geom::matrix_mm_from_iso;
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

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
    #[arg(long, default_value_t = 60.0)]
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
        if !(a.rate.is_finite() && a.rate > 0.0 && a.rate <= 10_000.0) {
            return Err(
                crate::UsageError(format!("--rate {}: must be in (0, 10000] Hz", a.rate)).into(),
            );
        }
        let file = if a.from == "sim" {
            None
        } else {
            Some(pose_lines::read(Path::new(&a.from))?)
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
        while server.client_count() == 0 {
            std::thread::sleep(Duration::from_millis(10));
        }
        let total = a.count.or(file.as_ref().map(|f| f.len() as u64));
        let period = Duration::from_secs_f64(1.0 / a.rate);
        let start = Instant::now();
        let mut k = 0u64;
        while total.is_none_or(|n| k < n) {
            let pose = match &file {
                Some(f) => f[(k as usize) % f.len()],
                None => pose_lines::gentle_head(k as f64 / a.rate),
            };
            let mut m = Message::transform(&a.device, &pose, Timestamp::now())?;
            if a.header_version >= 2 {
                m = m.with_metadata(vec![MetaEntry::text("TransformStatus", "OK")]);
                m.message_id = k as u32;
            }
            server.send(&m);
            k += 1;
            if let Some(wait) = (start + period * k as u32).checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
        }
        // Every pose written to the clients before closing (a client that stopped reading gets 2 s).
        server.flush(Duration::from_secs(2));
        let c = server.counters();
        let last = match &file {
            Some(f) => f[((k.max(1) - 1) as usize) % f.len()],
            None => pose_lines::gentle_head((k.max(1) - 1) as f64 / a.rate),
        };
        let t = matrix_mm_from_iso(&last);
        writeln!(
            out,
            "sent {k} poses to {} client(s) ({} dropped as slow); last at ({:.1}, {:.1}, {:.1}) mm",
            c.accepted,
            c.dropped_slow,
            t[(0, 3)],
            t[(1, 3)],
            t[(2, 3)]
        )?;
        Ok(())
    }
}
