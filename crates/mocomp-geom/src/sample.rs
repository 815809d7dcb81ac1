//! Timestamped pose samples and the `PoseSource` trait through which the control loop reads a
//! tracker, whatever it is (OpenIGTLink stream, IR+depth fiducial tracking, simulation).

use nalgebra::Isometry3;

/// One tracker sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// `tracker_from_marker` (e.g. `tracker_from_head`), metres.
    pub tracker_from_marker: Isometry3<f64>,
    /// When it was measured (acquisition time), seconds on the monotonic clock the loop uses.
    pub acquired_s: f64,
    /// Whether the tracker reported the marker as valid (seen, within its error limit).
    pub valid: bool,
    /// Registration error reported with the sample, metres (`NaN` when unknown).
    pub error_m: f64,
}

/// A source of tracker samples. `latest` never blocks: it returns the newest sample that has
/// arrived since the last call, or `None` when nothing new came.
pub trait PoseSource {
    /// The newest sample not yet returned, if any.
    fn latest(&mut self) -> Option<PoseSample>;

    /// How many times the thread feeding this source failed (panicked, or ended when nobody
    /// asked it to); it restarts by itself where it can. One atomic load: the loop asks every
    /// cycle, and names the failure as the reason it holds when samples stop.
    fn failures(&self) -> u64 {
        0
    }
}

/// A monotonic clock, seconds. The live system uses the machine's monotonic clock; the simulator
/// steps its own.
pub trait Clock: Send + Sync {
    /// Seconds since the clock's origin.
    fn now_s(&self) -> f64;
}

/// The machine's monotonic clock, seconds since it was created: the one clock the live system
/// uses (created at the edges and handed to the loop and the I/O threads).
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    origin: std::time::Instant,
}

impl MonotonicClock {
    /// A clock starting at 0 now.
    pub fn new() -> Self {
        Self {
            origin: std::time::Instant::now(),
        }
    }
}

impl Default for MonotonicClock {
    fn default() -> Self {
        Self::new()
    }
}

impl Clock for MonotonicClock {
    fn now_s(&self) -> f64 {
        self.origin.elapsed().as_secs_f64()
    }
}

/// A clock that moves only when told (the simulator's clock): deterministic runs.
#[derive(Debug, Default)]
pub struct SteppedClock {
    bits: std::sync::atomic::AtomicU64,
}

impl SteppedClock {
    /// A clock at `t` seconds.
    pub fn new(t: f64) -> Self {
        Self {
            bits: std::sync::atomic::AtomicU64::new(t.to_bits()),
        }
    }

    /// Sets the time.
    pub fn set(&self, t: f64) {
        self.bits
            .store(t.to_bits(), std::sync::atomic::Ordering::Release);
    }

    /// Advances the time by `dt` seconds.
    pub fn advance(&self, dt: f64) {
        self.set(self.now_s() + dt);
    }
}

impl Clock for SteppedClock {
    fn now_s(&self) -> f64 {
        f64::from_bits(self.bits.load(std::sync::atomic::Ordering::Acquire))
    }
}
