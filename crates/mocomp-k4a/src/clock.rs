//! A camera's device timestamps on the host's clock, and the frames it dropped. Pure.
//!
//! The device stamps each image at the middle of its exposure on its own clock; the host sees
//! it some time later (readout, USB, the depth engine). `host − device` is then the clocks'
//! offset plus that delay, and its least value over a recent window is the offset plus the
//! *least* delay: the frames that came fastest define the mapping, the slower ones are not
//! mistaken for an earlier exposure. The least delay itself is invisible from the host (a
//! constant a camera's datasheet or a flash test gives), so it is subtracted as configured.

/// How many recent frames the offset is the least over (10 s at 30 frames a second).
const WINDOW: usize = 300;

/// Maps device timestamps onto the host's clock.
#[derive(Debug, Clone)]
pub struct DeviceClock {
    /// `host − device` of recent frames, s (a ring).
    offsets: [f64; WINDOW],
    len: usize,
    next: usize,
    last_device_s: f64,
    least_delay_s: f64,
}

impl DeviceClock {
    /// A mapping that takes `least_delay_s` (exposure middle to the fastest arrival) off.
    pub fn new(least_delay_s: f64) -> Self {
        Self {
            offsets: [0.0; WINDOW],
            len: 0,
            next: 0,
            last_device_s: f64::NEG_INFINITY,
            least_delay_s,
        }
    }

    /// A frame stamped `device_usec` arrived at `host_s`: its exposure on the host's clock.
    pub fn acquired(&mut self, device_usec: u64, host_s: f64) -> f64 {
        let device_s = device_usec as f64 * 1e-6;
        if device_s < self.last_device_s {
            // The device's clock started again (the camera restarted): so does the mapping.
            self.len = 0;
            self.next = 0;
        }
        self.last_device_s = device_s;
        self.offsets[self.next] = host_s - device_s;
        self.next = (self.next + 1) % WINDOW;
        self.len = (self.len + 1).min(WINDOW);
        let least = self.offsets[..self.len]
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min);
        device_s + least - self.least_delay_s
    }
}

/// Counts the frames missing between consecutive device timestamps.
#[derive(Debug, Clone, Copy)]
pub struct Gaps {
    period_usec: f64,
    last_usec: Option<u64>,
}

impl Gaps {
    /// For a camera at `fps` frames a second.
    pub fn new(fps: u32) -> Self {
        Self {
            period_usec: 1e6 / f64::from(fps.max(1)),
            last_usec: None,
        }
    }

    /// The frames dropped before this one (0 when it follows on).
    pub fn dropped_before(&mut self, device_usec: u64) -> u64 {
        let dropped = match self.last_usec {
            Some(last) if device_usec > last => {
                let periods = (device_usec - last) as f64 / self.period_usec;
                if periods > 1.5 {
                    periods.round() as u64 - 1
                } else {
                    0
                }
            }
            _ => 0,
        };
        self.last_usec = Some(device_usec);
        dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fastest_arrivals_define_the_mapping_and_slow_ones_do_not_move_it() {
        // Device clock 1000 s behind the host; frames arrive 30 ms after exposure, some up to
        // 25 ms later still (a busy USB bus).
        let mut c = DeviceClock::new(0.030);
        let mut worst: f64 = 0.0;
        for k in 0..600u64 {
            let device_usec = 5_000_000 + k * 33_333;
            let exposure_host = device_usec as f64 * 1e-6 + 1000.0;
            let extra = [0.0, 0.025, 0.004, 0.011, 0.0, 0.019][(k % 6) as usize];
            let acquired = c.acquired(device_usec, exposure_host + 0.030 + extra);
            if k > 0 {
                worst = worst.max((acquired - exposure_host).abs());
            }
        }
        assert!(worst < 1e-9, "{worst}");
    }

    #[test]
    fn a_restarted_device_clock_starts_the_mapping_again() {
        let mut c = DeviceClock::new(0.0);
        c.acquired(9_000_000, 100.0);
        // The camera restarted: its clock is near 0 again, the host's went on.
        let t = c.acquired(1_000, 101.0);
        assert!((t - 101.0).abs() < 1e-12, "{t}");
    }

    #[test]
    fn gaps_count_the_frames_missing() {
        let mut g = Gaps::new(30);
        assert_eq!(g.dropped_before(1_000_000), 0);
        assert_eq!(g.dropped_before(1_033_333), 0);
        // Jitter of a third of a period is not a drop.
        assert_eq!(g.dropped_before(1_077_000), 0);
        // Three periods later: two missing.
        assert_eq!(g.dropped_before(1_177_000), 2);
        // A repeated or earlier stamp is no drop.
        assert_eq!(g.dropped_before(1_177_000), 0);
    }
}
