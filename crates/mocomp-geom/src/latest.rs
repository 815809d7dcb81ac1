//! A single-writer cell holding the newest [`PoseSample`], readable from another thread without
//! locks or allocation: a sequence lock over atomics (no `unsafe`).

use crate::{PoseSample, SeqLock};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};

/// The newest sample, with a version that grows with every publication.
#[derive(Debug, Default)]
pub struct LatestCell {
    cell: SeqLock<10>,
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
        self.cell.publish(&[
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
        ]);
    }

    /// The newest sample and its version (1, 2, … in publication order), or `None` before the
    /// first publication. Never blocks: retries only while a publication is in progress.
    pub fn read(&self) -> Option<(u64, PoseSample)> {
        let (version, v) = self.cell.read()?;
        let pose = Isometry3::from_parts(
            Translation3::new(v[0], v[1], v[2]),
            UnitQuaternion::new_unchecked(Quaternion::new(v[6], v[3], v[4], v[5])),
        );
        Some((
            version,
            PoseSample {
                tracker_from_marker: pose,
                acquired_s: v[7],
                valid: v[8] != 0.0,
                error_m: v[9],
            },
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
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
