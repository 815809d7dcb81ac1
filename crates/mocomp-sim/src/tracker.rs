//! A simulated optical tracker.
//!
//! [`TrackerSim`] is the model, pure and steppable: it acquires every marker at its rate from a
//! truth function, adds noise in position and rotation, loses the markers during dropouts, now and
//! then reports a jump (an outlier, as from a reflection taken for a fiducial), and hands each
//! observation out once its latency has passed. [`TrackerServer`] runs it in real time on a thread
//! and serves the observations over OpenIGTLink as TRANSFORM messages with a `TransformStatus`
//! (`OK`, or `INVALID` while a marker is lost), stamped with their acquisition time, as a PLUS
//! server does.

use crate::motion::MotionError;
use mocomp_geom::nalgebra::{Isometry3, UnitQuaternion, Vector3};
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The tracker's model. Units: Hz, seconds, metres, radians.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerModel {
    /// Samples per second.
    pub rate_hz: f64,
    /// Acquisition to sending, s.
    pub latency_s: f64,
    /// Position noise per axis (1σ), m.
    pub noise_m: f64,
    /// Rotation noise per axis (1σ), rad.
    pub noise_rad: f64,
    /// Dropouts (every marker lost) per second, on average (Poisson).
    pub dropouts_per_s: f64,
    /// How long a dropout lasts, s.
    pub dropout_s: f64,
    /// Probability that a sample is an outlier.
    pub outlier_probability: f64,
    /// An outlier's jump, m.
    pub outlier_m: f64,
    /// Seed of the noise, dropouts and outliers.
    pub seed: u64,
    /// The tracker computer's wall clock steps by this much (s) at `clock_step_at_s`, as NTP or
    /// an operator setting its clock does: every served timestamp after it carries the step
    /// (0: no step). Only the OpenIGTLink server's timestamps; the truth is unaffected.
    pub clock_step_s: f64,
    /// When the clock steps, s after the server started.
    pub clock_step_at_s: f64,
}

impl Default for TrackerModel {
    /// A clinical optical tracker: 60 Hz, 20 ms latency, 0.1 mm and 1 mrad (0.057°) per axis, no
    /// dropouts or outliers.
    fn default() -> Self {
        Self {
            rate_hz: 60.0,
            latency_s: 0.02,
            noise_m: 1e-4,
            noise_rad: 1e-3,
            dropouts_per_s: 0.0,
            dropout_s: 0.1,
            outlier_probability: 0.0,
            outlier_m: 0.05,
            seed: 1,
            clock_step_s: 0.0,
            clock_step_at_s: 0.0,
        }
    }
}

impl TrackerModel {
    /// Checks every parameter; the error names the first one out of range.
    pub fn validate(&self) -> Result<(), MotionError> {
        let check = |key, value: f64, ok: bool, problem| {
            if value.is_finite() && ok {
                Ok(())
            } else {
                Err(MotionError {
                    key,
                    value,
                    problem,
                })
            }
        };
        check(
            "rate_hz",
            self.rate_hz,
            (1.0..=2000.0).contains(&self.rate_hz),
            "must be in [1, 2000]",
        )?;
        check(
            "latency_s",
            self.latency_s,
            (0.0..=1.0).contains(&self.latency_s),
            "must be in [0, 1]",
        )?;
        check("noise_m", self.noise_m, self.noise_m >= 0.0, "must be ≥ 0")?;
        check(
            "noise_rad",
            self.noise_rad,
            self.noise_rad >= 0.0,
            "must be ≥ 0",
        )?;
        check(
            "dropouts_per_s",
            self.dropouts_per_s,
            self.dropouts_per_s >= 0.0,
            "must be ≥ 0",
        )?;
        check(
            "dropout_s",
            self.dropout_s,
            self.dropout_s >= 0.0,
            "must be ≥ 0",
        )?;
        check(
            "outlier_probability",
            self.outlier_probability,
            (0.0..=1.0).contains(&self.outlier_probability),
            "must be in [0, 1]",
        )?;
        check(
            "outlier_m",
            self.outlier_m,
            self.outlier_m >= 0.0,
            "must be ≥ 0",
        )?;
        check(
            "clock_step_s",
            self.clock_step_s,
            self.clock_step_s.abs() <= 1e6,
            "must be within ±10⁶ s",
        )?;
        check(
            "clock_step_at_s",
            self.clock_step_at_s,
            self.clock_step_at_s >= 0.0,
            "must be ≥ 0",
        )
    }

    /// The server's timestamp (its wall clock, s) of an acquisition at `acquired_s` after a
    /// start at wall time `wall0`, the clock step included.
    pub fn stamp_s(&self, wall0: f64, acquired_s: f64) -> f64 {
        let step = if self.clock_step_s != 0.0 && acquired_s >= self.clock_step_at_s {
            self.clock_step_s
        } else {
            0.0
        };
        wall0 + acquired_s + step
    }
}

/// One observation of one marker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Which marker (index into the truth function's markers).
    pub marker: usize,
    /// Acquisition time, s (the simulation's time).
    pub acquired_s: f64,
    /// `tracker_from_marker` as measured (the last seen pose while lost).
    pub tracker_from_marker: Isometry3<f64>,
    /// False while the marker is lost (a dropout, or out of view).
    pub valid: bool,
    /// True when this sample is a deliberate outlier (for the report; the receiver cannot know).
    pub outlier: bool,
}

/// The tracker model, stepped by its caller.
#[derive(Debug, Clone)]
pub struct TrackerSim {
    model: TrackerModel,
    rng: ChaCha8Rng,
    markers: usize,
    next_k: u64,
    dropout_until: f64,
    next_dropout: f64,
    last_seen: Vec<Option<Isometry3<f64>>>,
    pending: VecDeque<Observation>,
}

impl TrackerSim {
    /// A tracker observing `markers` markers, starting at time 0.
    pub fn new(model: TrackerModel, markers: usize) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(model.seed);
        let next_dropout = next_poisson(&mut rng, model.dropouts_per_s, 0.0);
        Self {
            model,
            rng,
            markers,
            next_k: 0,
            dropout_until: f64::NEG_INFINITY,
            next_dropout,
            last_seen: vec![None; markers],
            pending: VecDeque::new(),
        }
    }

    /// The model.
    pub fn model(&self) -> &TrackerModel {
        &self.model
    }

    /// The next acquisition time, s.
    pub fn next_acquisition_s(&self) -> f64 {
        self.next_k as f64 / self.model.rate_hz
    }

    /// When [`step`](Self::step) next has something to do, s.
    pub fn next_event_s(&self) -> f64 {
        let send = self
            .pending
            .front()
            .map_or(f64::INFINITY, |o| o.acquired_s + self.model.latency_s);
        send.min(self.next_acquisition_s())
    }

    /// Acquires every sample due by `now` from `truth(marker, t)` (the true `tracker_from_marker`
    /// at `t`, or `None` when out of view), then hands every observation whose latency has passed
    /// to `out`, oldest first.
    pub fn step(
        &mut self,
        now: f64,
        truth: &mut dyn FnMut(usize, f64) -> Option<Isometry3<f64>>,
        out: &mut dyn FnMut(&Observation),
    ) {
        while self.next_acquisition_s() <= now {
            let t = self.next_acquisition_s();
            self.next_k += 1;
            self.acquire(t, truth);
        }
        while let Some(o) = self.pending.front() {
            if o.acquired_s + self.model.latency_s > now {
                break;
            }
            if let Some(o) = self.pending.pop_front() {
                out(&o);
            }
        }
    }

    fn acquire(&mut self, t: f64, truth: &mut dyn FnMut(usize, f64) -> Option<Isometry3<f64>>) {
        let m = self.model;
        while self.next_dropout <= t {
            self.dropout_until = self.next_dropout + m.dropout_s;
            self.next_dropout = next_poisson(&mut self.rng, m.dropouts_per_s, self.next_dropout);
        }
        let lost = t < self.dropout_until;
        for marker in 0..self.markers {
            let seen = if lost { None } else { truth(marker, t) };
            let o = match seen {
                Some(true_pose) => {
                    let rng = &mut self.rng;
                    let mut gauss3 = || {
                        Vector3::new(
                            rng.sample::<f64, _>(StandardNormal),
                            rng.sample::<f64, _>(StandardNormal),
                            rng.sample::<f64, _>(StandardNormal),
                        )
                    };
                    let dp = gauss3() * m.noise_m;
                    let dr = gauss3() * m.noise_rad;
                    let mut p = true_pose;
                    p.translation.vector += dp;
                    p.rotation = UnitQuaternion::from_scaled_axis(dr) * p.rotation;
                    let outlier = m.outlier_probability > 0.0
                        && self.rng.random::<f64>() < m.outlier_probability;
                    if outlier {
                        let rng = &mut self.rng;
                        let dir = Vector3::new(
                            rng.sample::<f64, _>(StandardNormal),
                            rng.sample::<f64, _>(StandardNormal),
                            rng.sample::<f64, _>(StandardNormal),
                        );
                        if dir.norm() > 1e-9 {
                            p.translation.vector += dir.normalize() * m.outlier_m;
                        }
                    }
                    self.last_seen[marker] = Some(p);
                    Observation {
                        marker,
                        acquired_s: t,
                        tracker_from_marker: p,
                        valid: true,
                        outlier,
                    }
                }
                None => match self.last_seen[marker] {
                    Some(p) => Observation {
                        marker,
                        acquired_s: t,
                        tracker_from_marker: p,
                        valid: false,
                        outlier: false,
                    },
                    // Never seen: nothing to report yet.
                    None => continue,
                },
            };
            self.pending.push_back(o);
        }
    }
}

/// The next event of a Poisson process of `rate` after `t` (never, for rate 0).
fn next_poisson(rng: &mut ChaCha8Rng, rate: f64, t: f64) -> f64 {
    if rate <= 0.0 {
        return f64::INFINITY;
    }
    let u: f64 = rng.random::<f64>();
    t - (1.0 - u).ln() / rate
}

/// A marker the server observes: its device name and its true `tracker_from_marker` at a time
/// (seconds since the server started), or `None` when out of view.
pub struct TrackedMarker {
    /// OpenIGTLink device name, e.g. `HeadToTracker`.
    pub device: String,
    /// The truth.
    pub truth: Box<dyn FnMut(f64) -> Option<Isometry3<f64>> + Send>,
}

impl std::fmt::Debug for TrackedMarker {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrackedMarker")
            .field("device", &self.device)
            .finish_non_exhaustive()
    }
}

/// The tracker server could not start.
#[derive(Debug, thiserror::Error)]
pub enum TrackerError {
    /// A model parameter out of range.
    #[error("tracker model: {0}")]
    Model(#[from] MotionError),
    /// The address could not be bound.
    #[error("simulated tracker: cannot listen on {addr}: {source}")]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
    /// The thread could not be started.
    #[error("simulated tracker: cannot start its thread: {0}")]
    Thread(std::io::Error),
}

/// The tracker model run in real time, serving its markers over OpenIGTLink. Stops when dropped.
#[derive(Debug)]
pub struct TrackerServer {
    addr: SocketAddr,
    /// Shared with the thread; the last one dropped stops it.
    server: Arc<Server>,
    started: Instant,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl TrackerServer {
    /// Binds `bind` (e.g. `127.0.0.1:0`) and starts sending. Timestamps are this host's wall
    /// clock at acquisition (a receiver on this host may trust them).
    pub fn start(
        bind: &str,
        model: TrackerModel,
        markers: Vec<TrackedMarker>,
    ) -> Result<Self, TrackerError> {
        model.validate()?;
        let server =
            Server::bind(bind, ServerConfig::default()).map_err(|source| TrackerError::Bind {
                addr: bind.to_string(),
                source,
            })?;
        let addr = server.local_addr();
        let server = Arc::new(server);
        let serving = Arc::clone(&server);
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = Arc::clone(&stop);
        // Time 0 on both clocks at once: the monotonic one for the truth, the wall clock for the
        // timestamps (taken apart, the thread's start-up would sit between them and every
        // timestamp would be late by it).
        let started = Instant::now();
        let wall0 = Timestamp::now().to_secs_f64();
        let thread = std::thread::Builder::new()
            .name("sim-tracker".into())
            .spawn(move || serve(&serving, model, markers, (started, wall0), &stop2))
            .map_err(TrackerError::Thread)?;
        Ok(Self {
            addr,
            server,
            started,
            stop,
            thread: Some(thread),
        })
    }

    /// The address served.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Sends `m` to every client besides the markers' stream (a simulated device on the same
    /// server: a stimulator's STRING).
    pub fn send(&self, m: &Message) {
        self.server.send(m);
    }

    /// The instant of the markers' time 0: a marker's truth is asked for `t` seconds after it.
    pub fn started(&self) -> Instant {
        self.started
    }
}

fn serve(
    server: &Server,
    model: TrackerModel,
    mut markers: Vec<TrackedMarker>,
    (start, wall0): (Instant, f64),
    stop: &AtomicBool,
) {
    let stamp = |acquired_s| model.stamp_s(wall0, acquired_s);
    let mut sim = TrackerSim::new(model, markers.len());
    let devices: Vec<String> = markers.iter().map(|m| m.device.clone()).collect();
    while !stop.load(Ordering::Relaxed) {
        let now = start.elapsed().as_secs_f64();
        sim.step(
            now,
            &mut |i, t| markers.get_mut(i).and_then(|m| (m.truth)(t)),
            &mut |o| {
                let ts = Timestamp::from_secs_f64(stamp(o.acquired_s));
                let device = devices.get(o.marker).map_or("", String::as_str);
                if let Ok(m) = Message::transform(device, &o.tracker_from_marker, ts) {
                    let status = if o.valid { "OK" } else { "INVALID" };
                    server.send(&m.with_metadata(vec![MetaEntry::text("TransformStatus", status)]));
                }
            },
        );
        let wait = (sim.next_event_s() - start.elapsed().as_secs_f64()).clamp(0.0, 0.005);
        std::thread::sleep(Duration::from_secs_f64(wait));
    }
}

impl Drop for TrackerServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn truth(_: usize, t: f64) -> Option<Isometry3<f64>> {
        Some(Isometry3::new(
            Vector3::new(0.1 * t, 0.0, 1.0),
            Vector3::new(0.0, 0.0, 0.2 * t),
        ))
    }

    fn run(model: TrackerModel, markers: usize, until: f64, dt: f64) -> Vec<(f64, Observation)> {
        let mut sim = TrackerSim::new(model, markers);
        let mut got = Vec::new();
        let mut now = 0.0;
        while now <= until {
            sim.step(now, &mut truth, &mut |o| got.push((now, *o)));
            now += dt;
        }
        got
    }

    #[test]
    fn samples_come_at_the_rate_after_the_latency_with_the_noise_asked_for() {
        let model = TrackerModel {
            rate_hz: 50.0,
            latency_s: 0.03,
            noise_m: 2e-4,
            noise_rad: 2e-3,
            ..Default::default()
        };
        let got = run(model, 2, 20.0, 0.001);
        // Two markers, 50 Hz, 20 s, less the last 30 ms not yet sent.
        assert_eq!(got.len(), 2 * (20.0 * 50.0 - 1.0) as usize);
        let mut sq = [0.0; 2];
        for (now, o) in &got {
            let age = now - o.acquired_s;
            assert!((0.03 - 1e-9..0.031 + 1e-9).contains(&age), "age {age}");
            assert!(o.valid && !o.outlier);
            let t = truth(0, o.acquired_s).unwrap();
            sq[0] +=
                (o.tracker_from_marker.translation.vector - t.translation.vector).norm_squared();
            sq[1] += (o.tracker_from_marker.rotation * t.rotation.inverse())
                .scaled_axis()
                .norm_squared();
        }
        let n = got.len() as f64;
        // Three axes of σ: the RMS norm is σ√3, within 5 %.
        let (pos, rot) = ((sq[0] / n).sqrt(), (sq[1] / n).sqrt());
        assert!((pos / (2e-4 * 3f64.sqrt()) - 1.0).abs() < 0.05, "{pos}");
        assert!((rot / (2e-3 * 3f64.sqrt()) - 1.0).abs() < 0.05, "{rot}");
        // Deterministic for a seed.
        assert_eq!(got, run(model, 2, 20.0, 0.001));
    }

    #[test]
    fn dropouts_lose_every_marker_for_their_duration_and_outliers_jump() {
        let model = TrackerModel {
            dropouts_per_s: 0.5,
            dropout_s: 0.2,
            outlier_probability: 0.01,
            outlier_m: 0.05,
            noise_m: 0.0,
            noise_rad: 0.0,
            ..Default::default()
        };
        let got = run(model, 1, 100.0, 0.002);
        let invalid = got.iter().filter(|(_, o)| !o.valid).count() as f64 / got.len() as f64;
        // Expected lost fraction: 0.5/s · 0.2 s ≈ 10 % (overlaps make it a little less).
        assert!((0.06..0.13).contains(&invalid), "{invalid}");
        let outliers: Vec<_> = got.iter().filter(|(_, o)| o.outlier).collect();
        let frac = outliers.len() as f64 / got.len() as f64;
        assert!((0.005..0.015).contains(&frac), "{frac}");
        for (_, o) in outliers {
            let t = truth(0, o.acquired_s).unwrap();
            let jump = (o.tracker_from_marker.translation.vector - t.translation.vector).norm();
            assert!((jump - 0.05).abs() < 1e-9, "{jump}");
        }
        // A lost marker repeats its last seen pose, marked invalid.
        for w in got.windows(2) {
            if w[0].1.valid && !w[1].1.valid {
                assert_eq!(w[0].1.tracker_from_marker, w[1].1.tracker_from_marker);
            }
        }
    }

    #[test]
    fn bad_parameters_are_named() {
        let m = TrackerModel {
            latency_s: -0.1,
            ..Default::default()
        };
        assert_eq!(m.validate().unwrap_err().key, "latency_s");
        let m = TrackerModel {
            outlier_probability: 2.0,
            ..Default::default()
        };
        assert_eq!(m.validate().unwrap_err().key, "outlier_probability");
        let m = TrackerModel {
            clock_step_at_s: -1.0,
            ..Default::default()
        };
        assert_eq!(m.validate().unwrap_err().key, "clock_step_at_s");
    }

    #[test]
    fn a_stepped_clock_moves_every_timestamp_from_the_step_on() {
        let m = TrackerModel {
            clock_step_s: -1.5,
            clock_step_at_s: 4.0,
            ..Default::default()
        };
        assert_eq!(m.stamp_s(100.0, 3.999), 103.999);
        assert_eq!(m.stamp_s(100.0, 4.0), 102.5);
        assert_eq!(m.stamp_s(100.0, 10.0), 108.5);
        // No step: the wall clock as it was at the start, plus the time since.
        assert_eq!(TrackerModel::default().stamp_s(100.0, 10.0), 110.0);
    }
}
