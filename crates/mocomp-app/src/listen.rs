//! Listening to an OpenIGTLink server for one device (`mocomp listen`): each pose as it arrives,
//! to debug a clinic's set-up (is the tracker streaming, under which name, at what rate, with
//! which status).

use crate::AppError;
use mocomp_geom::nalgebra::Matrix4;
use mocomp_igtl::client::{Client, ClientConfig, ClientCounters, MonotonicClock, status_valid};
use mocomp_igtl::message::{Body, matrix_mm, pose_of};
use std::ops::ControlFlow;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What to listen to.
#[derive(Debug, Clone)]
pub struct ListenOptions {
    /// The server, `host:port`.
    pub addr: String,
    /// The device: a TRANSFORM device or a TDATA tool.
    pub device: String,
    /// Stop after this many poses.
    pub count: Option<u64>,
    /// Give up when no pose arrives for this long.
    pub timeout: Duration,
    /// Ask the server for a TDATA stream (STT_TDATA) after connecting.
    pub stt_tdata: bool,
}

/// One pose as received.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Heard {
    /// The message's timestamp, s since the Unix epoch (`None` when the sender sets none).
    pub t: Option<f64>,
    /// The sender's status says valid and the matrix is a rigid transform.
    pub valid: bool,
    /// tracker_from_marker, translation in mm, as sent.
    pub matrix_mm: Matrix4<f64>,
}

impl Heard {
    /// One line for a person: device, time, status and position (mm).
    pub fn line(&self, device: &str) -> String {
        let m = &self.matrix_mm;
        format!(
            "{device} t={} {} ({:.2}, {:.2}, {:.2}) mm",
            self.t.map_or_else(|| "none".into(), |t| format!("{t:.6}")),
            if self.valid { "valid" } else { "INVALID" },
            m[(0, 3)],
            m[(1, 3)],
            m[(2, 3)]
        )
    }

    /// One JSON object: `device`, `t`, `valid`, `tracker_from_marker` (4×4 rows, mm).
    pub fn json(&self, device: &str) -> String {
        #[derive(serde::Serialize)]
        struct Line<'a> {
            device: &'a str,
            t: Option<f64>,
            valid: bool,
            tracker_from_marker: [[f64; 4]; 4],
        }
        let m = &self.matrix_mm;
        let line = Line {
            device,
            t: self.t,
            valid: self.valid,
            tracker_from_marker: std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)])),
        };
        // A struct of numbers and a string always serialises.
        serde_json::to_string(&line).unwrap_or_default()
    }
}

/// What a listen heard in all: the client's counters and the last damage it named.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Listened {
    /// The client's counters.
    pub counters: ClientCounters,
    /// The last stream error, in words (a damaged message, a dropped stream, a reader failure).
    pub last_error: Option<String>,
}

/// What a listen heard in all, as one line: the poses, the messages, the damaged ones (and the
/// last damage named), the timestamps' faults and the reconnects.
pub fn counts_line(poses: u64, l: &Listened) -> String {
    let c = &l.counters;
    let damaged = c.crc_errors + c.malformed + c.fatal_errors + c.reader_failures;
    let mut line = format!(
        "{poses} poses; {} messages, {damaged} damaged ({} CRC errors, {} malformed, {} streams out of step, {} reader failures), {} zero timestamps, {} backwards, {} clock steps, {} reconnects",
        c.messages,
        c.crc_errors,
        c.malformed,
        c.fatal_errors,
        c.reader_failures,
        c.zero_timestamps,
        c.backwards_timestamps,
        c.clock_steps,
        c.connections.saturating_sub(1)
    );
    if damaged > 0
        && let Some(e) = &l.last_error
    {
        line.push_str(&format!("; last: {e}"));
    }
    line
}

/// What a listener's callback answers: go on, stop, or fail.
pub type Flow = Result<ControlFlow<()>, AppError>;

/// Listens until `count` poses of the device arrived (or forever, or until `each` says break),
/// telling `each` of every one; returns the client's counters. An [`AppError::Refused`] when none
/// arrives for `timeout`.
pub fn listen(
    o: &ListenOptions,
    each: &mut dyn FnMut(&Heard) -> Flow,
) -> Result<Listened, AppError> {
    let mut poses = 0u64;
    if o.count == Some(0) {
        return Ok(Listened::default());
    }
    listen_devices(o, &[o.device.as_str()], &mut |_, h| {
        poses += 1;
        let flow = each(h)?;
        Ok(if o.count.is_some_and(|n| poses >= n) {
            ControlFlow::Break(())
        } else {
            flow
        })
    })
}

/// Listens to each of `devices` (TRANSFORM devices or TDATA tools), telling `each` of every pose
/// with the index of its device, until `each` says break; `o.device` and `o.count` are not used.
/// An [`AppError::Refused`] when no pose of any arrives for `o.timeout`.
pub fn listen_devices(
    o: &ListenOptions,
    devices: &[&str],
    each: &mut dyn FnMut(usize, &Heard) -> Flow,
) -> Result<Listened, AppError> {
    let mut cfg = ClientConfig::new(&o.addr);
    cfg.device = devices.first().map(|d| d.to_string());
    cfg.keep_messages = 4096;
    cfg.start_tdata = o.stt_tdata.then_some(0);
    let client = Client::start(cfg, Arc::new(MonotonicClock::new()));
    let Some(rx) = client.take_messages() else {
        refuse!("the OpenIGTLink client has no message channel");
    };
    let mut last = Instant::now();
    loop {
        let Ok(r) = rx.recv_timeout(Duration::from_millis(100)) else {
            if last.elapsed() > o.timeout {
                let c = client.counters();
                refuse!(
                    "--igtl {}: no pose of {} for {:.1} s ({} messages, {} damaged, {} connections, last error: {})",
                    o.addr,
                    devices
                        .iter()
                        .map(|d| format!("{d:?}"))
                        .collect::<Vec<_>>()
                        .join(" or "),
                    o.timeout.as_secs_f64(),
                    c.messages,
                    c.crc_errors + c.malformed + c.fatal_errors + c.reader_failures,
                    c.connections,
                    client.last_error().unwrap_or_else(|| "none".into())
                );
            }
            continue;
        };
        let m = &r.message;
        for (index, device) in devices.iter().enumerate() {
            let floats = match &m.body {
                Body::Transform(f) if m.device == *device => Some(*f),
                Body::TData(tools) => tools.iter().find(|t| t.name == *device).map(|t| t.matrix),
                _ => None,
            };
            let Some(f) = floats else { continue };
            last = Instant::now();
            let flow = each(
                index,
                &Heard {
                    t: (!m.timestamp.is_none()).then(|| m.timestamp.to_secs_f64()),
                    valid: status_valid(m) && pose_of(&f).is_ok(),
                    matrix_mm: matrix_mm(&f),
                },
            )?;
            if flow.is_break() {
                return Ok(Listened {
                    counters: client.counters(),
                    last_error: client.last_error(),
                });
            }
        }
    }
}
