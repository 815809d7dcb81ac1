//! A single-writer cell holding the newest [`PoseSample`], readable from another thread without
//! locks or allocation: a sequence lock over atomics (no `unsafe`).

use mocomp_geom::PoseSample;
use mocomp_geom::nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use std::sync::atomic::{AtomicU64, Ordering, fence};

const WORDS: usize = 10;

/// The newest sample, with a version that grows with every publication.
#[derive(Debug)]
pub struct LatestCell {
    seq: AtomicU64,
    words: [AtomicU64; WORDS],
}

impl Default for LatestCell {
    fn default() -> Self {
        Self {
            seq: AtomicU64::new(0),
            words: std::array::from_fn(|_| AtomicU64::new(0)),
        }
    }
}

impl LatestCell {
    /// An empty cell.
    pub fn new() -> Self {
        Self::default()
    }

    /// Publishes a sample. Only one thread may publish.
    pub fn publish(&self, s: &PoseSample) {
        let t = s.tracker_from_marker.translation.vector;
        let q = s.tracker_from_marker.rotation.coords; // i, j, k, w
        let values = [
            t.x,
            t.y,
            t.z,
            q[0],
            q[1],
            q[2],
            q[3],
            s.acquired_s,
            if s.valid { 1.0 } else { 0.0 },
            s.error_m,
        ];
        let v = self.seq.load(Ordering::Relaxed);
        self.seq.store(v.wrapping_add(1), Ordering::Relaxed);
        fence(Ordering::Release);
        for (w, x) in self.words.iter().zip(values) {
            w.store(x.to_bits(), Ordering::Relaxed);
        }
        self.seq.store(v.wrapping_add(2), Ordering::Release);
    }

    /// The newest sample and its version (1, 2, … in publication order), or `None` before the
    /// first publication. Never blocks: retries only while a publication is in progress.
    pub fn read(&self) -> Option<(u64, PoseSample)> {
        loop {
            let s1 = self.seq.load(Ordering::Acquire);
            if s1 == 0 {
                return None;
            }
            if s1 & 1 == 1 {
                std::hint::spin_loop();
                continue;
            }
            let mut v = [0f64; WORDS];
            for (x, w) in v.iter_mut().zip(&self.words) {
                *x = f64::from_bits(w.load(Ordering::Relaxed));
            }
            fence(Ordering::Acquire);
            if self.seq.load(Ordering::Relaxed) == s1 {
                let pose = Isometry3::from_parts(
                    Translation3::new(v[0], v[1], v[2]),
                    UnitQuaternion::new_unchecked(Quaternion::new(v[6], v[3], v[4], v[5])),
                );
                return Some((
                    s1 / 2,
                    PoseSample {
                        tracker_from_marker: pose,
                        acquired_s: v[7],
                        valid: v[8] != 0.0,
                        error_m: v[9],
                    },
                ));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_geom::nalgebra::Vector3;
    use std::sync::Arc;

    fn sample(k: f64) -> PoseSample {
        PoseSample {
            tracker_from_marker: Isometry3::new(
                Vector3::new(k, 2.0 * k, 3.0 * k),
                Vector3::new(0.1, 0.2, 0.3),
            ),
            acquired_s: k,
            valid: true,
            error_m: f64::NAN,
        }
    }

    #[test]
    fn readers_never_see_a_torn_sample() {
        let cell = Arc::new(LatestCell::new());
        assert!(cell.read().is_none());
        let writer = {
            let cell = Arc::clone(&cell);
            std::thread::spawn(move || {
                for k in 1..=200_000 {
                    cell.publish(&sample(f64::from(k)));
                }
            })
        };
        let mut last = 0;
        let mut reads = 0;
        while !writer.is_finished() || reads == 0 {
            if let Some((v, s)) = cell.read() {
                let k = s.acquired_s;
                let t = s.tracker_from_marker.translation.vector;
                assert_eq!((t.x, t.y, t.z), (k, 2.0 * k, 3.0 * k), "consistent fields");
                assert!(v >= last, "versions grow");
                last = v;
                reads += 1;
            }
        }
        writer.join().unwrap();
        let (v, s) = cell.read().unwrap();
        assert_eq!(v, 200_000);
        assert_eq!(s.acquired_s, 200_000.0);
        assert!(s.error_m.is_nan());
    }
}
