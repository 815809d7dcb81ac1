//! The offset from a sender's clock to ours when the two are not synchronised: estimated from
//! the smallest delay seen, and re-based when the sender's clock steps.
//!
//! `receive time − sender time` is the offset plus the network delay, and delay only adds, so
//! the smallest value seen is the best estimate; it adapts slowly upwards for clock drift.
//! A tracker computer's clock can also step (NTP correcting it, an operator setting it). Forward,
//! the new smallest value is taken at once. Backward, every later message looks older by the step;
//! a network stall looks the same for its backlog, but fresh messages come straight after it.
//! So a message later than the smallest delay by more than [`STEP_S`] is taken as old, and only
//! when every message for [`CONFIRM_S`] is that late is it the clock: the offset is re-based on
//! the smallest of them. Until then those samples are old (the loop holds for a stale tracker),
//! which is the safe reading of a stamp it cannot yet explain.
//!
//! Pure: the times are given.

/// A delay beyond the smallest by more than this (s) is not the network's: a stall's backlog, or
/// the sender's clock stepped back.
pub const STEP_S: f64 = 0.25;

/// Every message this long (s, our clock) later than [`STEP_S`]: the sender's clock stepped.
pub const CONFIRM_S: f64 = 0.5;

/// How fast the offset follows a delay above the smallest (drift), per message.
const DRIFT_GAIN: f64 = 1e-3;

/// The estimate, for one connection.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct OffsetEstimator {
    offset: Option<f64>,
    /// Since when (our clock) every message was late by more than [`STEP_S`], and the smallest
    /// offset among them.
    late: Option<(f64, f64)>,
}

/// What one message said about the offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observed {
    /// Our clock = the sender's + this (s), for this message.
    pub offset_s: f64,
    /// The sender's clock stepped by this much (s; positive: forward) and the offset was
    /// re-based.
    pub step_s: Option<f64>,
}

impl OffsetEstimator {
    /// Forgets everything (a new connection: maybe another sender).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// The offset now, if any message was seen.
    pub fn offset_s(&self) -> Option<f64> {
        self.offset
    }

    /// Takes a message stamped `sent_s` (the sender's clock) received at `now_s` (ours).
    pub fn observe(&mut self, now_s: f64, sent_s: f64) -> Observed {
        let est = now_s - sent_s;
        let Some(o) = self.offset else {
            self.offset = Some(est);
            return Observed {
                offset_s: est,
                step_s: None,
            };
        };
        let mut step_s = None;
        let offset = if est < o {
            // Smaller delay than ever: a better estimate, or (by more than any jitter) the
            // sender's clock stepped forward.
            self.late = None;
            if o - est > STEP_S {
                step_s = Some(o - est);
            }
            est
        } else if est - o <= STEP_S {
            self.late = None;
            o + (est - o) * DRIFT_GAIN
        } else {
            let (since, least) = self.late.map_or((now_s, est), |(s, l)| (s, l.min(est)));
            if now_s - since >= CONFIRM_S {
                self.late = None;
                step_s = Some(o - least);
                least
            } else {
                self.late = Some((since, least));
                o
            }
        };
        self.offset = Some(offset);
        // A late message unconfirmed keeps the offset as it was: the sample is as old as it
        // looks.
        Observed {
            offset_s: offset,
            step_s,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    /// Messages every `dt` from `t0` to `t1` (our clock), `sent = now − offset − delay(k)`.
    fn feed(
        e: &mut OffsetEstimator,
        (t0, t1, dt): (f64, f64, f64),
        offset: f64,
        delay: impl Fn(usize) -> f64,
    ) -> Vec<Observed> {
        let n = ((t1 - t0) / dt).round() as usize;
        (0..n)
            .map(|k| {
                let now = t0 + k as f64 * dt;
                e.observe(now, now - offset - delay(k))
            })
            .collect()
    }

    fn jitter(k: usize) -> f64 {
        0.001 + 0.004 * ((k * 7919) % 13) as f64 / 13.0
    }

    #[test]
    fn the_smallest_delay_is_the_offset_and_jitter_is_not_a_step() {
        let mut e = OffsetEstimator::default();
        let got = feed(&mut e, (0.0, 10.0, 1.0 / 60.0), 100.0, jitter);
        assert!(got.iter().all(|o| o.step_s.is_none()));
        // The smallest delay (1 ms), with a little drift adaptation upwards.
        let o = e.offset_s().unwrap();
        assert!((o - 100.001).abs() < 2e-4, "{o}");
    }

    #[test]
    fn a_backward_step_is_read_as_old_until_confirmed_then_rebased() {
        let mut e = OffsetEstimator::default();
        feed(&mut e, (0.0, 5.0, 1.0 / 60.0), 100.0, jitter);
        // The sender's clock steps back 1 s: our clock − its clock grows by 1 s.
        let got = feed(&mut e, (5.0, 7.0, 1.0 / 60.0), 101.0, jitter);
        let first = got.iter().position(|o| o.step_s.is_some()).unwrap();
        // Confirmed after CONFIRM_S of messages all that late, not before.
        let at = 5.0 + first as f64 / 60.0;
        assert!(
            (5.0 + CONFIRM_S..5.0 + CONFIRM_S + 0.02).contains(&at),
            "{at}"
        );
        // Until then read with the old offset (the samples look 1 s old: the loop holds).
        assert!(
            got[..first]
                .iter()
                .all(|o| (o.offset_s - 100.001).abs() < 1e-3)
        );
        let step = got[first].step_s.unwrap();
        assert!((step + 1.0).abs() < 5e-3, "{step}");
        // Re-based: fresh again, and one step only.
        assert!(
            got[first..]
                .iter()
                .all(|o| (o.offset_s - 101.001).abs() < 5e-3)
        );
        assert_eq!(got.iter().filter(|o| o.step_s.is_some()).count(), 1);
    }

    #[test]
    fn a_forward_step_is_taken_at_once() {
        let mut e = OffsetEstimator::default();
        feed(&mut e, (0.0, 5.0, 1.0 / 60.0), 100.0, jitter);
        let got = feed(&mut e, (5.0, 6.0, 1.0 / 60.0), 99.0, jitter);
        let step = got[0].step_s.unwrap();
        // The first message after the step may be a little late: within the jitter.
        assert!((step - 1.0).abs() < 5e-3, "{step}");
        assert!((got[0].offset_s - 99.0).abs() < 6e-3);
        assert_eq!(got.iter().filter(|o| o.step_s.is_some()).count(), 1);
    }

    #[test]
    fn a_stall_backlog_is_old_and_is_not_a_step() {
        let mut e = OffsetEstimator::default();
        feed(&mut e, (0.0, 5.0, 1.0 / 60.0), 100.0, jitter);
        // A 2 s stall: 120 messages arrive at once, as old as they are, then fresh ones.
        let mut got = Vec::new();
        for k in 0..120 {
            let sent = 5.0 - 100.0 + k as f64 / 60.0;
            got.push(e.observe(7.0 + k as f64 * 1e-5, sent));
        }
        got.extend(feed(&mut e, (7.01, 9.0, 1.0 / 60.0), 100.0, jitter));
        assert!(got.iter().all(|o| o.step_s.is_none()));
        // The backlog kept the offset: its samples are as old as they are.
        assert!(
            got[..100]
                .iter()
                .all(|o| (o.offset_s - 100.001).abs() < 1e-3)
        );
        assert!((e.offset_s().unwrap() - 100.001).abs() < 2e-3);
    }

    #[test]
    fn a_reset_forgets_the_sender() {
        let mut e = OffsetEstimator::default();
        feed(&mut e, (0.0, 1.0, 0.1), 100.0, |_| 0.0);
        e.reset();
        assert_eq!(e.offset_s(), None);
        assert_eq!(e.observe(2.0, 1.0).offset_s, 1.0);
    }
}
