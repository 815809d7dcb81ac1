//! A single-writer cell of `N` numbers, readable from other threads without locks, blocking or
//! allocation: a sequence lock over atomics (no `unsafe`). The newest-sample cells of the tracker
//! client and the robot client are built on it.

use std::sync::atomic::{AtomicU64, Ordering, fence};

/// The newest `N` values published, with a version that grows with every publication.
#[derive(Debug)]
pub struct SeqLock<const N: usize> {
    seq: AtomicU64,
    words: [AtomicU64; N],
}

impl<const N: usize> Default for SeqLock<N> {
    fn default() -> Self {
        Self {
            seq: AtomicU64::new(0),
            words: std::array::from_fn(|_| AtomicU64::new(0)),
        }
    }
}

impl<const N: usize> SeqLock<N> {
    /// An empty cell.
    pub fn new() -> Self {
        Self::default()
    }

    /// Publishes `values`. Only one thread may publish.
    pub fn publish(&self, values: &[f64; N]) {
        let v = self.seq.load(Ordering::Relaxed);
        self.seq.store(v.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (w, x) in self.words.iter().zip(values) {
            w.store(x.to_bits(), Ordering::Relaxed);
        }
        self.seq.store(v.wrapping_add(2), Ordering::Release);
    }

    /// The version of the newest publication (1, 2, …), 0 before the first.
    pub fn version(&self) -> u64 {
        self.seq.load(Ordering::Acquire) / 2
    }

    /// The newest values and their version (1, 2, … in publication order), or `None` before the
    /// first publication. Never blocks: retries only while a publication is in progress.
    pub fn read(&self) -> Option<(u64, [f64; N])> {
        loop {
            let s1 = self.seq.load(Ordering::Acquire);
            if s1 == 0 {
                return None;
            }
            if s1 & 1 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let mut v = [0f64; N];
            for (x, w) in v.iter_mut().zip(&self.words) {
                *x = f64::from_bits(w.load(Ordering::Relaxed));
            }
            fence(Ordering::Acquire);
            if self.seq.load(Ordering::Relaxed) == s1 {
                return Some((s1 / 2, v));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn readers_never_see_a_torn_publication() {
        let cell = Arc::new(SeqLock::<8>::new());
        assert!(cell.read().is_none());
        assert_eq!(cell.version(), 0);
        let writer = {
            let cell = Arc::clone(&cell);
            std::thread::spawn(move || {
                for k in 1..=200_000u32 {
                    let k = f64::from(k);
                    cell.publish(&std::array::from_fn(|i| k * (i as f64 + 1.0)));
                }
            })
        };
        let mut last = 0;
        let mut reads = 0;
        while !writer.is_finished() || reads == 0 {
            if let Some((v, x)) = cell.read() {
                for (i, xi) in x.iter().enumerate() {
                    assert_eq!(*xi, x[0] * (i as f64 + 1.0), "consistent words");
                }
                assert!(v >= last, "versions grow");
                last = v;
                reads += 1;
            }
        }
        writer.join().unwrap();
        let (v, x) = cell.read().unwrap();
        assert_eq!(v, 200_000);
        assert_eq!(cell.version(), 200_000);
        assert_eq!(x[7], 1_600_000.0);
    }
}
