//! A joint-space transit: the straight line in joint space from where the arm is to a
//! pre-approach configuration, as a UR program's `movej` would go, parametrised by the largest
//! joint's travel (rad).
//!
//! The shell path ([`crate::planner::ShellPath`]) lives in the head frame and stays on one IK
//! branch: from a start far from the head it swings with every turn of the head (its far end
//! moves by the head's angular speed times the lever), and from a start on another branch it has
//! no solution at all. A transit is planned once, in the base frame, to the goal's approach axis
//! away from the head on a branch the goal can be tracked on, and the shell path takes over from
//! there. Pure math: no allocation, no I/O; the loop checks the samples against the head before it
//! starts.

/// A straight joint-space segment from `start` to `end`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointPath {
    start: [f64; 6],
    end: [f64; 6],
    /// The largest joint's travel, rad: the path's length.
    length: f64,
}

impl JointPath {
    /// The segment from `start` to `end`.
    pub fn new(start: [f64; 6], end: [f64; 6]) -> Self {
        let length = (0..6).fold(0.0f64, |m, j| m.max((end[j] - start[j]).abs()));
        Self { start, end, length }
    }

    /// Where it starts.
    pub fn start(&self) -> &[f64; 6] {
        &self.start
    }

    /// Where it ends.
    pub fn end(&self) -> &[f64; 6] {
        &self.end
    }

    /// The largest joint's travel, rad.
    pub fn length(&self) -> f64 {
        self.length
    }

    /// The joints at parameter `s` (rad of the largest joint's travel, clamped to the path): every
    /// joint moves in proportion, so all arrive together as in a `movej`.
    pub fn at(&self, s: f64) -> [f64; 6] {
        let f = if self.length > 0.0 {
            (s / self.length).clamp(0.0, 1.0)
        } else {
            1.0
        };
        std::array::from_fn(|j| self.start[j] + (self.end[j] - self.start[j]) * f)
    }

    /// The time a trapezoidal profile at `speed` (rad/s) and `accel` (rad/s²) of the largest
    /// joint takes, s.
    pub fn duration(&self, speed: f64, accel: f64) -> f64 {
        if self.length <= 0.0 {
            return 0.0;
        }
        if self.length < speed * speed / accel {
            2.0 * (self.length / accel).sqrt()
        } else {
            self.length / speed + speed / accel
        }
    }
}

/// One step of a speed- and acceleration-limited profile along a path of `length`: from `s` at
/// `s_dot`, towards `want` speed (0 to wait), so that it can still stop at the end. Returns the
/// new `(s, s_dot)`.
pub fn profile_step(s: f64, s_dot: f64, length: f64, want: f64, accel: f64, dt: f64) -> (f64, f64) {
    let remaining = (length - s).max(0.0);
    // The discrete braking curve: a step at v, then one of `accel * dt` less each cycle, covers
    // v²/2a + v·dt/2. The continuous curve √(2a·rem) ignores the second term and arrives at the
    // end still moving, at about ten cycles' worth of deceleration.
    let brake = accel * ((dt * dt / 4.0 + 2.0 * remaining / accel).sqrt() - dt / 2.0);
    let want = want.min(brake);
    let v = want.clamp(s_dot - accel * dt, s_dot + accel * dt).max(0.0);
    ((s + v * dt).min(length), v)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use proptest::prelude::*;

    fn joints() -> impl Strategy<Value = [f64; 6]> {
        proptest::array::uniform6(-6.0f64..6.0)
    }

    proptest! {
        #![proptest_config(mocomp_testkit::proptest_config(512, 29))]

        #[test]
        fn ends_where_it_says_and_moves_every_joint_in_proportion(a in joints(), b in joints(), f in 0.0f64..1.0) {
            let p = JointPath::new(a, b);
            prop_assert_eq!(p.at(0.0), a);
            let end = p.at(p.length());
            for j in 0..6 {
                prop_assert!((end[j] - b[j]).abs() < 1e-12);
            }
            let mid = p.at(f * p.length());
            let k = (0..6).max_by(|&i, &j| (b[i] - a[i]).abs().total_cmp(&(b[j] - a[j]).abs())).unwrap();
            // The largest joint moves by exactly s; every other by its share.
            prop_assert!(((mid[k] - a[k]).abs() - f * p.length()).abs() < 1e-9);
            for j in 0..6 {
                prop_assert!(((mid[j] - a[j]) - f * (b[j] - a[j])).abs() < 1e-9);
            }
        }

        #[test]
        fn the_profile_reaches_the_end_within_its_duration_and_never_exceeds_its_limits(
            length in 0.01f64..4.0, speed in 0.1f64..2.0, accel in 0.2f64..5.0,
        ) {
            let p = JointPath::new([0.0; 6], [length, 0.0, 0.0, 0.0, 0.0, 0.0]);
            let dt = 0.002;
            let (mut s, mut v) = (0.0, 0.0);
            let mut t = 0.0;
            while s < length && t < 100.0 {
                let (s1, v1) = profile_step(s, v, length, speed, accel, dt);
                prop_assert!(v1 <= speed + 1e-12, "speed {v1}");
                prop_assert!((v1 - v).abs() <= accel * dt + 1e-12, "accel");
                prop_assert!(s1 >= s);
                (s, v) = (s1, v1);
                t += dt;
            }
            // It arrives at rest: the stop after the last step is within one cycle's deceleration.
            prop_assert!(v <= accel * dt + 1e-12, "arrived at {v} rad/s");
            let ideal = p.duration(speed, accel);
            // Discrete steps arrive within a few cycles of the continuous profile, never sooner
            // than its limits allow.
            prop_assert!(t <= ideal + 0.05 + 0.02 * ideal, "took {t} s, ideal {ideal} s");
            prop_assert!(t >= ideal - 2.0 * dt, "took {t} s, faster than the profile allows ({ideal} s)");
        }
    }

    #[test]
    fn a_profile_asked_to_wait_stops_and_stays() {
        let (mut s, mut v) = (0.0, 0.0);
        for _ in 0..200 {
            (s, v) = profile_step(s, v, 1.0, 0.5, 1.0, 0.002);
        }
        assert!(v > 0.3 && s > 0.05, "moving: {s} {v}");
        for _ in 0..1000 {
            (s, v) = profile_step(s, v, 1.0, 0.0, 1.0, 0.002);
        }
        assert_eq!(v, 0.0);
        let here = s;
        (s, _) = profile_step(s, v, 1.0, 0.0, 1.0, 0.002);
        assert_eq!(s, here);
    }
}
