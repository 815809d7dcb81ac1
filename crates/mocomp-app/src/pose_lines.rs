//! `mocomp serve-poses`: poses from a file of JSON lines, or a gently moving head, served over
//! OpenIGTLink at a steady rate ([`serve`]).

use crate::{AppError, Context};
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Translation3, Vector3};
use mocomp_geom::quat_from_rotvec;
use mocomp_igtl::server::Server;
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use std::path::Path;
use std::time::{Duration, Instant};

/// A head in front of the tracker at time `t` (s): 1 m away, drifting and nodding gently.
pub fn gentle_head(t: f64) -> Isometry3<f64> {
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

/// Reads a poses file: JSON lines, each with `tracker_from_marker` (4×4 rows, mm), such as
/// `mocomp listen --json` output or a rendered `truth.jsonl`. Errors name the file and line.
pub fn read(path: &Path) -> Result<Vec<Isometry3<f64>>, AppError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).what(|| format!("--from {name}: cannot read"))?;
    let mut poses = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let at = || format!("--from {name}: line {}", i + 1);
        let v: serde_json::Value = serde_json::from_str(line).what(at)?;
        let Some(rows) = v.get("tracker_from_marker") else {
            return Err(AppError::Config(format!(
                "{}: no \"tracker_from_marker\"",
                at()
            )));
        };
        let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().unwrap_or(f64::NAN));
        poses.push(iso_from_matrix_mm(&m, 1e-4).what(at)?);
    }
    if poses.is_empty() {
        return Err(AppError::Config(format!("--from {name}: no poses")));
    }
    Ok(poses)
}

/// What [`serve`] sends.
#[derive(Debug, Clone)]
pub struct ServeOptions {
    /// The device name.
    pub device: String,
    /// Poses per second.
    pub rate_hz: f64,
    /// Stop after this many (`None`: a file once, the gentle head forever).
    pub count: Option<u64>,
    /// Header version: 1, or 2 with `TransformStatus` metadata (as PLUS and Slicer send).
    pub header_version: u16,
}

/// What [`serve`] did.
#[derive(Debug, Clone, Copy)]
pub struct Served {
    /// Poses sent.
    pub sent: u64,
    /// Clients accepted.
    pub clients: u64,
    /// Messages dropped for clients too slow to read them.
    pub dropped_slow: u64,
    /// The last pose sent (`tracker_from_marker`).
    pub last: Isometry3<f64>,
}

/// Waits for a client of `server`, then sends `poses` (the gentle head when `None`, a file's
/// poses in a loop otherwise) at `opts.rate_hz` on the monotonic clock, each on time however
/// long the previous send took, and flushes them to the clients (a client that stopped reading
/// gets 2 s).
pub fn serve(
    server: &Server,
    poses: Option<&[Isometry3<f64>]>,
    opts: &ServeOptions,
) -> Result<Served, AppError> {
    let pose_at = |k: u64| match poses {
        Some(f) if !f.is_empty() => f[(k as usize) % f.len()],
        _ => gentle_head(k as f64 / opts.rate_hz),
    };
    while server.client_count() == 0 {
        std::thread::sleep(Duration::from_millis(10));
    }
    let total = opts.count.or(poses.map(|f| f.len() as u64));
    let period = Duration::from_secs_f64(1.0 / opts.rate_hz);
    let start = Instant::now();
    let mut k = 0u64;
    while total.is_none_or(|n| k < n) {
        let mut m = Message::transform(&opts.device, &pose_at(k), Timestamp::now())
            .what(|| format!("--device {}", opts.device))?;
        if opts.header_version >= 2 {
            m = m.with_metadata(vec![MetaEntry::text("TransformStatus", "OK")]);
            m.message_id = k as u32;
        }
        server.send(&m);
        k += 1;
        if let Some(wait) = (start + period * k as u32).checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    if !server.flush(Duration::from_secs(2)) {
        refuse!(
            "sent {k} poses, but a client had not taken them all 2 s after the last: not every pose was delivered"
        );
    }
    let c = server.counters();
    Ok(Served {
        sent: k,
        clients: c.accepted,
        dropped_slow: c.dropped_slow,
        last: pose_at(k.max(1) - 1),
    })
}
