//! `mocomp listen` and `mocomp serve-poses`: OpenIGTLink on the command line, to debug a clinic's
//! set-up (is the tracker streaming, under which name, at what rate, with which status).

use anyhow::{Context, Result, bail};
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Translation3, Vector3};
use mocomp_geom::{iso_from_matrix_mm, matrix_mm_from_iso, quat_from_rotvec};
use mocomp_igtl::client::{Client, ClientConfig, MonotonicClock, status_valid};
use mocomp_igtl::message::{Body, pose_of};
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use serde::Serialize;
use std::io::Write;
use std::path::Path;
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

/// Options of `mocomp listen`.
#[derive(Debug)]
pub struct ListenArgs<'a> {
    /// `host:port`.
    pub addr: &'a str,
    /// Device (TRANSFORM/POSITION name or TDATA tool).
    pub device: &'a str,
    /// Stop after this many poses.
    pub count: Option<u64>,
    /// Give up when nothing arrives for this long.
    pub timeout: Duration,
    /// Ask for a TDATA stream.
    pub stt_tdata: bool,
    /// JSON lines.
    pub json: bool,
}

/// `mocomp listen`.
pub fn listen(out: &mut impl Write, a: &ListenArgs<'_>) -> Result<()> {
    let mut cfg = ClientConfig::new(a.addr);
    cfg.device = Some(a.device.to_string());
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
                if last.elapsed() > a.timeout {
                    let c = client.counters();
                    return Err(NothingReceived(format!(
                        "--igtl {}: no pose of {:?} for {:.1} s ({} messages, {} connections, last error: {})",
                        a.addr,
                        a.device,
                        a.timeout.as_secs_f64(),
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
            Body::Transform(f) if m.device == a.device => Some(*f),
            Body::TData(tools) => tools.iter().find(|t| t.name == a.device).map(|t| t.matrix),
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
                device: a.device,
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

/// Where `serve-poses` gets its poses.
#[derive(Debug)]
pub enum PoseFeed<'a> {
    /// JSON lines with `tracker_from_marker` (4×4, mm), e.g. `mocomp listen --json` output or a
    /// rendered `truth.jsonl`.
    File(&'a Path),
    /// A head gently moving in front of the tracker.
    Sim,
}

/// Options of `mocomp serve-poses`.
#[derive(Debug)]
pub struct ServeArgs<'a> {
    /// Address to bind.
    pub host: &'a str,
    /// Port.
    pub port: u16,
    /// Source.
    pub feed: PoseFeed<'a>,
    /// Device name.
    pub device: &'a str,
    /// Messages per second.
    pub rate_hz: f64,
    /// Stop after this many (default: the file's poses once, or forever for `sim`).
    pub count: Option<u64>,
    /// Header version.
    pub header_version: u16,
}

/// A head in front of the tracker: 1 m away, drifting and nodding (a stand-in until the
/// simulation crate brings patient-motion profiles).
fn sim_pose(t: f64) -> Isometry3<f64> {
    let w = std::f64::consts::TAU;
    let p = Vector3::new(
        0.010 * (w * 0.05 * t).sin(),
        0.005 * (w * 0.11 * t).sin(),
        1.0 + 0.004 * (w * 0.07 * t).sin(),
    );
    let r = Vector3::new(
        0.08 * (w * 0.25 * t).sin(),
        0.05 * (w * 0.13 * t).sin(),
        0.02 * (w * 0.07 * t).sin(),
    );
    Isometry3::from_parts(Translation3::from(p), quat_from_rotvec(&r))
}

fn read_feed(path: &Path) -> Result<Vec<Isometry3<f64>>> {
    let name = path.display().to_string();
    let text =
        std::fs::read_to_string(path).with_context(|| format!("--from {name}: cannot read"))?;
    let mut poses = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let v: serde_json::Value =
            serde_json::from_str(line).with_context(|| format!("--from {name}: line {}", i + 1))?;
        let rows = v.get("tracker_from_marker").with_context(|| {
            format!("--from {name}: line {}: no \"tracker_from_marker\"", i + 1)
        })?;
        let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().unwrap_or(f64::NAN));
        poses.push(
            iso_from_matrix_mm(&m, 1e-4)
                .with_context(|| format!("--from {name}: line {}", i + 1))?,
        );
    }
    if poses.is_empty() {
        return Err(crate::UsageError(format!("--from {name}: no poses")).into());
    }
    Ok(poses)
}

/// `mocomp serve-poses`.
pub fn serve(out: &mut impl Write, a: &ServeArgs<'_>) -> Result<()> {
    if !(a.rate_hz.is_finite() && a.rate_hz > 0.0 && a.rate_hz <= 10_000.0) {
        return Err(
            crate::UsageError(format!("--rate {}: must be in (0, 10000] Hz", a.rate_hz)).into(),
        );
    }
    let file = match &a.feed {
        PoseFeed::File(p) => Some(read_feed(p)?),
        PoseFeed::Sim => None,
    };
    let server = Server::bind(&format!("{}:{}", a.host, a.port), ServerConfig::default())
        .with_context(|| format!("--igtl-port {}: cannot listen on {}", a.port, a.host))?;
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
    let period = Duration::from_secs_f64(1.0 / a.rate_hz);
    let start = Instant::now();
    let mut k = 0u64;
    while total.is_none_or(|n| k < n) {
        let pose = match &file {
            Some(f) => f[(k as usize) % f.len()],
            None => sim_pose(k as f64 / a.rate_hz),
        };
        let mut m = Message::transform(a.device, &pose, Timestamp::now())?;
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
        None => sim_pose((k.max(1) - 1) as f64 / a.rate_hz),
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
