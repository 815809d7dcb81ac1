//! `mocomp listen`: the poses an OpenIGTLink server streams, to debug a clinic's set-up (is the
//! tracker streaming, under which name, at what rate, with which status).

use anyhow::{Result, bail};
use clap::Args;
use mocomp_geom::nalgebra::Matrix4;
use mocomp_igtl::client::{Client, ClientConfig, MonotonicClock, status_valid};
use mocomp_igtl::message::{Body, pose_of};
use serde::Serialize;
use std::io::Write;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Nothing arrived: a well-formed request that could not be met (exit code 1).
#[derive(Debug)]
pub struct NothingReceived(pub String);

impl std::fmt::Display for NothingReceived {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NothingReceived {}

#[derive(Serialize)]
struct PoseJson<'a> {
    device: &'a str,
    /// Message timestamp, seconds since the Unix epoch (null when the sender sets none).
    t: Option<f64>,
    valid: bool,
    tracker_from_marker: [[f64; 4]; 4],
}

fn rows_mm(m: &Matrix4<f64>) -> [[f64; 4]; 4] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
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
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        crate::args::positive("--timeout", self.timeout)?;
        self.listen(out, Duration::from_secs_f64(self.timeout))
    }

    fn listen(&self, out: &mut dyn Write, timeout: Duration) -> Result<()> {
        let a = self;
        let mut cfg = ClientConfig::new(&a.igtl);
        cfg.device = Some(a.device.clone());
        cfg.keep_messages = 4096;
        cfg.start_tdata = a.stt_tdata.then_some(0);
        let client = Client::start(cfg, Arc::new(MonotonicClock::new()));
        let Some(rx) = client.messages() else {
            bail!("no message channel")
        };
        let mut poses = 0u64;
        let mut last = Instant::now();
        loop {
            if a.count.is_some_and(|n| poses >= n) {
                break;
            }
            let r = match rx.recv_timeout(Duration::from_millis(100)) {
                Ok(r) => r,
                Err(_) => {
                    if last.elapsed() > timeout {
                        let c = client.counters();
                        return Err(NothingReceived(format!(
                        "--igtl {}: no pose of {:?} for {:.1} s ({} messages, {} connections, last error: {})",
                        a.igtl,
                        a.device,
                        timeout.as_secs_f64(),
                        c.messages,
                        c.connections,
                        client.last_error().unwrap_or_else(|| "none".into())
                    ))
                    .into());
                    }
                    continue;
                }
            };
            let m = &r.message;
            let floats = match &m.body {
                Body::Transform(f) if m.device == *a.device => Some(*f),
                Body::TData(tools) => tools.iter().find(|t| t.name == *a.device).map(|t| t.matrix),
                _ => None,
            };
            let Some(f) = floats else { continue };
            last = Instant::now();
            poses += 1;
            let matrix = mocomp_igtl::message::matrix_mm(&f);
            let valid = status_valid(m) && pose_of(&f).is_ok();
            let t = (!m.timestamp.is_none()).then(|| m.timestamp.to_secs_f64());
            if a.json {
                let j = PoseJson {
                    device: &a.device,
                    t,
                    valid,
                    tracker_from_marker: rows_mm(&matrix),
                };
                writeln!(out, "{}", serde_json::to_string(&j)?)?;
            } else {
                writeln!(
                    out,
                    "{} t={} {} ({:.2}, {:.2}, {:.2}) mm",
                    a.device,
                    t.map(|t| format!("{t:.6}"))
                        .unwrap_or_else(|| "none".into()),
                    if valid { "valid" } else { "INVALID" },
                    matrix[(0, 3)],
                    matrix[(1, 3)],
                    matrix[(2, 3)]
                )?;
            }
            out.flush()?;
        }
        let c = client.counters();
        eprintln!(
            "{poses} poses; {} messages, {} CRC errors, {} malformed, {} zero timestamps, {} backwards, {} reconnects",
            c.messages,
            c.crc_errors,
            c.malformed,
            c.zero_timestamps,
            c.backwards_timestamps,
            c.connections.saturating_sub(1)
        );
        Ok(())
    }
}
