//! Poses and times into ROS 2 messages, and back. Pure.

use crate::msg::{Point, Pose, Quaternion, Time, Transform, Vector3};
use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion};

/// A time in seconds since the Unix epoch as `builtin_interfaces/Time` (the nearest
/// nanosecond; NaN and out-of-range times are the epoch).
pub fn time(unix_s: f64) -> Time {
    if !unix_s.is_finite() || unix_s < 0.0 || unix_s >= f64::from(i32::MAX) {
        return Time::default();
    }
    // Seconds and fraction apart: the nanoseconds since the epoch do not fit an f64's mantissa.
    let mut sec = unix_s.floor();
    let mut nanosec = ((unix_s - sec) * 1e9).round();
    if nanosec >= 1e9 {
        sec += 1.0;
        nanosec -= 1e9;
    }
    Time {
        sec: sec as i32,
        nanosec: nanosec.clamp(0.0, 999_999_999.0) as u32,
    }
}

/// The time's seconds since the Unix epoch.
pub fn seconds(t: &Time) -> f64 {
    f64::from(t.sec) + f64::from(t.nanosec) * 1e-9
}

/// A pose as `geometry_msgs/Pose`.
pub fn pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    Pose {
        position: Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: quaternion(&iso.rotation),
    }
}

/// A pose as `geometry_msgs/Transform`.
pub fn transform(iso: &Isometry3<f64>) -> Transform {
    let t = iso.translation.vector;
    Transform {
        translation: Vector3 {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        rotation: quaternion(&iso.rotation),
    }
}

fn quaternion(q: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

/// Why a received pose is not one.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseError {
    /// A value that is not a number.
    #[error("{0} is not finite")]
    NotFinite(&'static str),
    /// The quaternion is far from unit length (its norm).
    #[error("orientation: the quaternion's norm is {0}, not 1")]
    NotUnit(f64),
}

/// A received `geometry_msgs/Pose` as an isometry. The quaternion is normalised when its norm is
/// within 1 % of 1 (senders round); further off, or not finite, it is refused.
pub fn iso(p: &Pose) -> Result<Isometry3<f64>, PoseError> {
    let (t, q) = (&p.position, &p.orientation);
    if !(t.x.is_finite() && t.y.is_finite() && t.z.is_finite()) {
        return Err(PoseError::NotFinite("position"));
    }
    let raw = mocomp_geom::nalgebra::Quaternion::new(q.w, q.x, q.y, q.z);
    let norm = raw.norm();
    if !norm.is_finite() {
        return Err(PoseError::NotFinite("orientation"));
    }
    if (norm - 1.0).abs() > 0.01 {
        return Err(PoseError::NotUnit(norm));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(t.x, t.y, t.z),
        UnitQuaternion::from_quaternion(raw),
    ))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Vector3 as V3;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(mocomp_testkit::proptest_config(256, 14))]

        #[test]
        fn a_pose_survives_the_message(
            x in -2.0..2.0f64, y in -2.0..2.0f64, z in -2.0..2.0f64,
            rx in -3.0..3.0f64, ry in -3.0..3.0f64, rz in -3.0..3.0f64,
        ) {
            let a = Isometry3::new(V3::new(x, y, z), V3::new(rx, ry, rz));
            let b = iso(&pose(&a)).unwrap();
            prop_assert!((a.translation.vector - b.translation.vector).norm() < 1e-12);
            prop_assert!(a.rotation.angle_to(&b.rotation) < 1e-9);
            let t = transform(&a);
            prop_assert_eq!(t.translation.x, x);
            prop_assert!((t.rotation.w.abs() - a.rotation.w.abs()).abs() < 1e-15);
        }

        #[test]
        fn a_time_survives_to_the_nanosecond(s in 0.0..2.0e9f64) {
            let t = time(s);
            prop_assert!(t.nanosec < 1_000_000_000);
            prop_assert!((seconds(&t) - s).abs() < 1e-6);
        }
    }

    #[test]
    fn times_and_poses_that_are_not_are_refused_or_zero() {
        assert_eq!(time(f64::NAN), Time::default());
        assert_eq!(time(-1.0), Time::default());
        assert_eq!(
            time(1_700_000_000.25),
            Time {
                sec: 1_700_000_000,
                nanosec: 250_000_000
            }
        );
        let mut p = pose(&Isometry3::identity());
        p.orientation.w = 2.0;
        assert_eq!(iso(&p), Err(PoseError::NotUnit(2.0)));
        p.orientation.w = 1.005;
        assert!(iso(&p).is_ok(), "a rounded quaternion is normalised");
        p.position.y = f64::NAN;
        assert_eq!(iso(&p), Err(PoseError::NotFinite("position")));
    }
}
