//! Commands sent and not yet acknowledged, by sequence number, in a fixed ring (no allocation):
//! what the command delay is measured from and what the controller may still take.

/// Up to `N` commands in flight, each with a value of its own (when it was sent, the setpoint
/// it carried), oldest first. More than `N` forgets the oldest.
#[derive(Debug, Clone)]
pub(super) struct InFlight<T: Copy, const N: usize> {
    sent: [(i32, T); N],
    head: usize,
    len: usize,
}

impl<T: Copy, const N: usize> InFlight<T, N> {
    /// None in flight (`fill` only fills the storage).
    pub(super) fn new(fill: T) -> Self {
        Self {
            sent: [(0, fill); N],
            head: 0,
            len: 0,
        }
    }

    /// Command `seq` was sent with `value`.
    pub(super) fn push(&mut self, seq: i32, value: T) {
        if self.len == N {
            self.head = (self.head + 1) % N;
            self.len -= 1;
        }
        self.sent[(self.head + self.len) % N] = (seq, value);
        self.len += 1;
    }

    /// A state shows command `acked` taken, and with it every command sent before (sequence
    /// numbers wrap): they leave the ring; the value `acked` was sent with, if it was in it.
    pub(super) fn acknowledge(&mut self, acked: i32) -> Option<T> {
        let mut found = None;
        while self.len > 0 {
            let (seq, value) = self.sent[self.head];
            if acked.wrapping_sub(seq) < 0 {
                break;
            }
            if seq == acked {
                found = Some(value);
            }
            self.head = (self.head + 1) % N;
            self.len -= 1;
        }
        found
    }

    /// The values of the commands in flight, oldest first.
    pub(super) fn values(&self) -> impl Iterator<Item = &T> + '_ {
        (0..self.len).map(move |k| &self.sent[(self.head + k) % N].1)
    }

    /// How many are in flight.
    #[cfg(test)]
    pub(super) fn len(&self) -> usize {
        self.len
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn acknowledging_takes_the_command_and_those_before_it_across_the_wrap() {
        let mut r: InFlight<u32, 4> = InFlight::new(0);
        let start = i32::MAX - 1;
        for k in 0..3 {
            r.push(start.wrapping_add(k), k as u32);
        }
        // Not sent yet (older than all): nothing leaves.
        assert_eq!(r.acknowledge(start.wrapping_sub(1)), None);
        assert_eq!(r.len(), 3);
        // The second, past i32::MAX: it and the first leave, its value comes back.
        assert_eq!(r.acknowledge(start.wrapping_add(1)), Some(1));
        assert_eq!(r.values().copied().collect::<Vec<_>>(), vec![2]);
        // Again: already gone.
        assert_eq!(r.acknowledge(start.wrapping_add(1)), None);
        // A newer command than any sent (one not in the ring) takes all.
        assert_eq!(r.acknowledge(start.wrapping_add(10)), None);
        assert_eq!(r.len(), 0);
    }

    #[test]
    fn more_than_it_holds_forgets_the_oldest() {
        let mut r: InFlight<u32, 4> = InFlight::new(0);
        for k in 0..6 {
            r.push(k as i32, k);
        }
        assert_eq!(r.values().copied().collect::<Vec<_>>(), vec![2, 3, 4, 5]);
        assert_eq!(r.acknowledge(1), None);
        assert_eq!(r.acknowledge(3), Some(3));
        assert_eq!(r.values().copied().collect::<Vec<_>>(), vec![4, 5]);
    }
}
