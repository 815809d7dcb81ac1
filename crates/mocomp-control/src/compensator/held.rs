//! The setpoints the controller may be holding when the next one lands, and the box that next
//! one must stay in so that the controller never sees a jump (URControl's C204A3).
//!
//! The controller judges a setpoint against the one it took before, over the time since it took
//! that one. Which one that is, the loop does not know: the newest it has acknowledged, or any
//! sent since, which may land a period after it. One period after the one it has (a late
//! setpoint taken alone, the next ones a period later) is the worst case: two or more of the
//! loop's steps then land as one. Bounding every setpoint against all of them (the newest
//! acknowledged over the time since it was taken, the rest over one period) keeps any landing
//! order within the joint's maximum speed, however the network or the controller's reader
//! bunches them. Pure: fixed storage, no allocation.

use super::in_flight::InFlight;

/// Setpoints sent and not yet acknowledged that are remembered. More in flight than this (a
/// controller that stopped acknowledging) forgets the oldest, which only loosens the bound.
const IN_FLIGHT: usize = 16;

/// The setpoints the controller may hold: the newest acknowledged, and those sent since.
#[derive(Debug, Clone)]
pub(super) struct HeldSetpoints {
    /// The newest acknowledged setpoint and the controller time of the first state that showed
    /// it taken, s.
    acked: Option<([f64; 6], f64)>,
    /// Sent, not yet acknowledged.
    sent: InFlight<[f64; 6], IN_FLIGHT>,
}

impl HeldSetpoints {
    /// Nothing sent.
    pub(super) fn new() -> Self {
        Self {
            acked: None,
            sent: InFlight::new([0.0; 6]),
        }
    }

    /// Forgets everything: the controller holds none of them (its program starts again).
    pub(super) fn clear(&mut self) {
        *self = Self::new();
    }

    /// Setpoint `q` was sent as command `seq`.
    pub(super) fn note_sent(&mut self, seq: i32, q: [f64; 6]) {
        self.sent.push(seq, q);
    }

    /// A state at controller time `controller_s` shows command `acked` taken (a state that
    /// shows it again changes nothing: it left the ring the first time).
    pub(super) fn acknowledge(&mut self, acked: i32, controller_s: f64) {
        if let Some(q) = self.sent.acknowledge(acked) {
            self.acked = Some((q, controller_s));
        }
    }

    /// The range joint `j`'s next setpoint must stay in, answering a state at controller time
    /// `now_s`, to imply no more than `max_speed` (rad/s) against any setpoint the controller
    /// may hold when it lands (no sooner than a `period` from now). Unbounded until one is
    /// acknowledged; the middle of the setpoints when they are spread wider than any one
    /// setpoint can meet.
    pub(super) fn range(&self, j: usize, now_s: f64, period: f64, max_speed: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        // A controller that has acknowledged none of them says nothing of what it holds.
        let Some((acked, taken_s)) = self.acked else {
            return (lo, hi);
        };
        let mut within = |q: f64, reach: f64| {
            lo = lo.max(q - reach);
            hi = hi.min(q + reach);
        };
        within(acked[j], max_speed * (now_s - taken_s + period).max(period));
        for q in self.sent.values() {
            within(q[j], max_speed * period);
        }
        if lo > hi {
            let mid = 0.5 * (lo + hi);
            (mid, mid)
        } else {
            (lo, hi)
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    const P: f64 = 0.002;

    #[test]
    fn nothing_acknowledged_bounds_nothing_and_a_clear_forgets() {
        let mut h = HeldSetpoints::new();
        assert_eq!(h.range(0, 1.0, P, 3.0), (f64::NEG_INFINITY, f64::INFINITY));
        h.note_sent(1, [0.5; 6]);
        h.note_sent(2, [0.5; 6]);
        assert_eq!(h.range(0, 1.0, P, 3.0), (f64::NEG_INFINITY, f64::INFINITY));
        h.acknowledge(1, 1.0);
        assert_eq!(h.range(0, 1.0, P, 3.0), (0.5 - 0.006, 0.5 + 0.006));
        h.clear();
        assert_eq!(h.range(0, 1.0, P, 3.0), (f64::NEG_INFINITY, f64::INFINITY));
    }

    #[test]
    fn in_flight_setpoints_bound_over_a_period_the_acknowledged_over_its_age() {
        let mut h = HeldSetpoints::new();
        h.note_sent(7, [0.0; 6]);
        h.note_sent(8, [0.004; 6]);
        h.note_sent(9, [0.008; 6]);
        // 7 taken at 1.000 s; 8 and 9 in flight at 1.004 s: the next lands at 1.006 s or later.
        h.acknowledge(7, 1.000);
        h.acknowledge(7, 1.004); // seen again: still taken at 1.000 s
        let (lo, hi) = h.range(0, 1.004, P, 3.0);
        assert!((lo - (0.008 - 0.006)).abs() < 1e-12, "{lo}");
        assert!((hi - (0.004 + 0.006)).abs() < 1e-12, "{hi}");
        // 9 acknowledged (8 with it): 9 alone, over the time since it was taken.
        h.acknowledge(9, 1.006);
        let (lo, hi) = h.range(0, 1.010, P, 3.0);
        assert!((lo - (0.008 - 3.0 * 0.006)).abs() < 1e-12, "{lo}");
        assert!((hi - (0.008 + 3.0 * 0.006)).abs() < 1e-12, "{hi}");
    }

    #[test]
    fn setpoints_spread_wider_than_one_can_meet_give_their_middle() {
        let mut h = HeldSetpoints::new();
        h.note_sent(1, [0.0; 6]);
        h.note_sent(2, [0.1; 6]);
        h.acknowledge(1, 0.0);
        let (lo, hi) = h.range(3, 0.0, P, 1.0);
        assert_eq!(lo, hi);
        assert!((lo - 0.05).abs() < 1e-12, "{lo}");
    }

    #[test]
    fn more_in_flight_than_remembered_forgets_the_oldest_and_sequence_numbers_wrap() {
        let mut h = HeldSetpoints::new();
        let mut seq = i32::MAX - 4;
        h.note_sent(seq, [0.0; 6]);
        h.acknowledge(seq, 0.0);
        for k in 0..(IN_FLIGHT + 4) {
            seq = seq.wrapping_add(1);
            h.note_sent(seq, [k as f64 * 1e-3; 6]);
        }
        assert_eq!(h.sent.len(), IN_FLIGHT);
        // The newest IN_FLIGHT are kept (4e-3 … 19e-3 rad; with the oldest the least would be
        // 0), spread wider than 1 rad/s · 2 ms can meet: the middle of 0.019 - 0.002 and
        // 0.004 + 0.002, 0.0 rad being acknowledged long enough ago to reach both.
        let (lo, hi) = h.range(0, 1.0, P, 1.0);
        assert_eq!(lo, hi);
        assert!((lo - 0.0115).abs() < 1e-12, "{lo}");
        // Acknowledging past the wrap takes the acknowledged one off and all before it.
        h.acknowledge(seq.wrapping_sub(1), 1.0);
        assert_eq!(h.sent.len(), 1);
        assert_eq!(h.acked.map(|a| a.0[0]), Some(18.0 * 1e-3));
    }
}
