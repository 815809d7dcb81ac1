//! The robot's recent joints, to compare a marker sample with the robot where it was when the
//! sample was acquired (a tracker's samples are tens of milliseconds old when they arrive).

/// How many states are kept: at 500 Hz, a quarter of a second.
pub const HISTORY: usize = 128;

/// A ring of `(time, joints)`, oldest first, of fixed size: pushing allocates nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointHistory {
    ring: [(f64, [f64; 6]); HISTORY],
    /// The oldest entry's index.
    start: usize,
    len: usize,
}

impl Default for JointHistory {
    fn default() -> Self {
        Self {
            ring: [(f64::NAN, [0.0; 6]); HISTORY],
            start: 0,
            len: 0,
        }
    }
}

impl JointHistory {
    /// Adds the joints at `t_s` (times must not go back); the oldest is dropped when full.
    pub fn push(&mut self, t_s: f64, q: [f64; 6]) {
        // A time that does not advance (or NaN) is not a new state.
        let advances = self.len == 0
            || t_s.partial_cmp(&self.get(self.len - 1).0) == Some(std::cmp::Ordering::Greater);
        if !advances {
            return;
        }
        if self.len == HISTORY {
            self.start = (self.start + 1) % HISTORY;
            self.len -= 1;
        }
        let i = (self.start + self.len) % HISTORY;
        self.ring[i] = (t_s, q);
        self.len += 1;
    }

    fn get(&self, k: usize) -> (f64, [f64; 6]) {
        self.ring[(self.start + k) % HISTORY]
    }

    /// The joints at `t_s`, interpolated between the states kept; `None` before the oldest or
    /// after the newest.
    pub fn at(&self, t_s: f64) -> Option<[f64; 6]> {
        let k = (0..self.len).find(|&k| self.get(k).0 >= t_s)?;
        let (t1, q1) = self.get(k);
        if k == 0 {
            return (t1 - t_s < 1e-9).then_some(q1);
        }
        let (t0, q0) = self.get(k - 1);
        let s = ((t_s - t0) / (t1 - t0)).clamp(0.0, 1.0);
        Some(std::array::from_fn(|j| q0[j] + (q1[j] - q0[j]) * s))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn joints_between_states_are_interpolated_and_outside_them_unknown() {
        let mut h = JointHistory::default();
        assert_eq!(h.at(0.0), None);
        for k in 0..300 {
            let t = k as f64 * 0.002;
            h.push(t, [t, -t, 0.0, 0.0, 0.0, 1.0]);
        }
        // The newest 128 are kept: from 0.344 s to 0.598 s.
        assert_eq!(h.at(0.3), None);
        assert_eq!(h.at(0.6), None);
        let q = h.at(0.4511).unwrap();
        assert!((q[0] - 0.4511).abs() < 1e-12 && (q[1] + 0.4511).abs() < 1e-12);
        assert_eq!(h.at(0.598).unwrap()[0], 0.598);
        // A time that goes back is ignored.
        h.push(0.1, [9.0; 6]);
        assert_eq!(h.at(0.598).unwrap()[0], 0.598);
    }
}
