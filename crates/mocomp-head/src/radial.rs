//! How far a head reaches from its centre in each direction: the planner's shell around the
//! head is this radius plus a margin, so a path travels outside everything the head has on each
//! ray (an ear's rim, not the skull behind it). A mesh's radius is cast once per direction of a
//! 2° latitude–longitude table at start-up and interpolated between.

use mocomp_geom::nalgebra::{Point3, Vector3};

/// Table steps per half turn of latitude (so 2° a step).
const STEPS: usize = 90;

/// The farthest surface point along each direction from a centre.
#[derive(Debug, Clone)]
pub struct RadialMap {
    centre: Point3<f64>,
    /// Row-major: latitude index (0 at −z … STEPS at +z), then longitude (2·STEPS, wrapping).
    radii: Vec<f64>,
}

impl RadialMap {
    /// The map about `centre`: `farthest(origin, direction)` says how far the surface reaches
    /// from `centre` along the unit `direction` (`None`: nothing there, radius 0).
    pub fn new(centre: Point3<f64>, farthest: impl Fn(&Vector3<f64>) -> Option<f64>) -> Self {
        let mut radii = Vec::with_capacity((STEPS + 1) * 2 * STEPS);
        for i in 0..=STEPS {
            let theta = std::f64::consts::PI * i as f64 / STEPS as f64;
            for j in 0..2 * STEPS {
                let phi = std::f64::consts::PI * j as f64 / STEPS as f64;
                let d = Vector3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    -theta.cos(),
                );
                radii.push(farthest(&d).unwrap_or(0.0));
            }
        }
        Self { centre, radii }
    }

    /// The centre.
    pub fn centre(&self) -> Point3<f64> {
        self.centre
    }

    /// The radius along the unit direction `d`, interpolated between the table's directions.
    pub fn radius_along(&self, d: &Vector3<f64>) -> f64 {
        let theta = (-d.z).clamp(-1.0, 1.0).acos() / std::f64::consts::PI * STEPS as f64;
        let phi =
            d.y.atan2(d.x).rem_euclid(std::f64::consts::TAU) / std::f64::consts::PI * STEPS as f64;
        let (i, j) = (
            (theta.floor() as usize).min(STEPS - 1),
            (phi.floor() as usize).min(2 * STEPS - 1),
        );
        let (fi, fj) = ((theta - i as f64).clamp(0.0, 1.0), phi - j as f64);
        let j1 = (j + 1) % (2 * STEPS);
        let at = |i: usize, j: usize| self.radii[i * 2 * STEPS + j];
        let lo = at(i, j) + (at(i, j1) - at(i, j)) * fj;
        let hi = at(i + 1, j) + (at(i + 1, j1) - at(i + 1, j)) * fj;
        lo + (hi - lo) * fi
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sphere_has_its_radius_everywhere_and_an_ellipsoid_near_it() {
        let s = RadialMap::new(Point3::new(0.1, 0.0, 0.0), |_| Some(0.09));
        let r = Vector3::new(0.075, 0.095, 0.11);
        let radial = |d: &Vector3<f64>| 1.0 / d.component_div(&r).norm();
        let e = RadialMap::new(Point3::origin(), |d| Some(radial(d)));
        let mut rng = mocomp_testkit::SplitMix64(3);
        for _ in 0..2000 {
            let d = Vector3::new(
                rng.next_f64() - 0.5,
                rng.next_f64() - 0.5,
                rng.next_f64() - 0.5,
            )
            .normalize();
            assert!((s.radius_along(&d) - 0.09).abs() < 1e-12);
            // 2° steps: within 0.1 mm of the ellipsoid's radius.
            assert!((e.radius_along(&d) - radial(&d)).abs() < 1e-4, "{d}");
        }
        for d in [Vector3::z(), -Vector3::z(), Vector3::x(), -Vector3::y()] {
            assert!((e.radius_along(&d) - radial(&d)).abs() < 1e-9, "{d}");
        }
    }
}
