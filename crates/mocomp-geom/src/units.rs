//! Unit conversions, by name. Inside mocomp everything is metres and radians; these are the only
//! places where millimetres and degrees are converted, at the I/O edges that use them.

/// Millimetres in one metre.
pub const MM_PER_M: f64 = 1000.0;

/// Metres to millimetres.
#[inline]
pub fn m_to_mm(metres: f64) -> f64 {
    metres * MM_PER_M
}

/// Millimetres to metres.
#[inline]
pub fn mm_to_m(millimetres: f64) -> f64 {
    millimetres / MM_PER_M
}

/// Degrees to radians.
#[inline]
pub fn deg_to_rad(degrees: f64) -> f64 {
    degrees.to_radians()
}

/// Radians to degrees.
#[inline]
pub fn rad_to_deg(radians: f64) -> f64 {
    radians.to_degrees()
}

/// Wraps an angle into `(-π, π]`.
#[inline]
pub fn wrap_pi(angle: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    // Fast paths for the common cases (no `fmod`).
    if angle > -PI && angle <= PI {
        return angle;
    }
    if angle > PI && angle <= 3.0 * PI {
        return angle - TAU;
    }
    if angle <= -PI && angle > -3.0 * PI {
        return angle + TAU;
    }
    let mut a = angle % TAU; // (-2π, 2π)
    if a > PI {
        a -= TAU;
    } else if a <= -PI {
        a += TAU;
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn conversions_round_trip() {
        assert_eq!(m_to_mm(0.4125), 412.5);
        assert_eq!(mm_to_m(412.5), 0.4125);
        assert!((deg_to_rad(180.0) - PI).abs() < 1e-15);
        assert!((rad_to_deg(PI / 2.0) - 90.0).abs() < 1e-12);
    }

    #[test]
    fn wrap_pi_range() {
        assert_eq!(wrap_pi(PI), PI);
        assert!((wrap_pi(-PI) - PI).abs() < 1e-15);
        assert!((wrap_pi(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
        assert!((wrap_pi(-7.0) - (-7.0 + 2.0 * PI)).abs() < 1e-15);
        assert_eq!(wrap_pi(0.25), 0.25);
        assert!((wrap_pi(3.0 * PI) - PI).abs() < 1e-15);
        assert!((wrap_pi(-3.0 * PI) - PI).abs() < 1e-15);
        assert!((wrap_pi(100.0) - (100.0 - 32.0 * PI)).abs() < 1e-13);
        assert!(wrap_pi(f64::NAN).is_nan());
        for k in -200..200 {
            let a = k as f64 * 0.1;
            let w = wrap_pi(a);
            assert!(w > -PI && w <= PI, "{a} -> {w}");
            assert!(((a - w) / (2.0 * PI) - ((a - w) / (2.0 * PI)).round()).abs() < 1e-12);
        }
    }
}
