//! A curve on the scalp between two points, in the plane through them and a third: the curve the
//! 10-20 system measures its percentages along. Each point of it is the scalp's outermost point
//! on a ray from the chord's midpoint, so a fold of the mesh inside the head (an ear canal, the
//! inner face of a segmented skull) never enters it.

use crate::NavError;
use mocomp_geom::nalgebra::{Point3, Unit, Vector3};
use mocomp_head::HeadShape;

/// Rays per half-turn: about 0.5 mm between neighbours on an adult's sagittal curve.
const STEPS: usize = 720;

/// A polyline on the scalp with its length so far at each vertex.
#[derive(Debug, Clone)]
pub(crate) struct Section {
    points: Vec<Point3<f64>>,
    run: Vec<f64>,
}

impl Section {
    /// The curve from `from` to `to` through the side of the chord where `via` lies, in their
    /// plane. `names` are `from`'s and `to`'s, for the errors.
    pub(crate) fn new(
        scalp: &dyn HeadShape,
        from: &Point3<f64>,
        to: &Point3<f64>,
        via: &Point3<f64>,
        names: (&str, &str),
    ) -> Result<Self, NavError> {
        let o = nalgebra_mid(from, to);
        let u = from - o;
        let w = via - o;
        let side = w - u * (w.dot(&u) / u.norm_squared().max(f64::MIN_POSITIVE));
        if u.norm() < 1e-3 || side.norm() < 1e-3 {
            return Err(NavError::SectionDegenerate {
                from: names.0.to_string(),
                to: names.1.to_string(),
            });
        }
        let (u, v) = (u.normalize(), side.normalize());
        let b = scalp.bounds();
        let reach = (b.max - b.min).norm() + (o - nalgebra_mid(&b.min, &b.max)).norm();
        let mut points = Vec::with_capacity(STEPS + 1);
        for i in 0..=STEPS {
            let a = std::f64::consts::PI * i as f64 / STEPS as f64;
            let d = u * a.cos() + v * a.sin();
            let inward = Unit::new_unchecked(-d);
            let hit = scalp
                .ray_hit(&(o + d * reach), &inward, reach)
                .ok_or_else(|| NavError::SectionMissesScalp {
                    from: names.0.to_string(),
                    to: names.1.to_string(),
                })?;
            points.push(hit.point);
        }
        let mut run = Vec::with_capacity(points.len());
        let mut total = 0.0;
        for (i, p) in points.iter().enumerate() {
            if i > 0 {
                total += (p - points[i - 1]).norm();
            }
            run.push(total);
        }
        Ok(Self { points, run })
    }

    /// Its length, m.
    pub(crate) fn length(&self) -> f64 {
        self.run.last().copied().unwrap_or(0.0)
    }

    /// The point `share` (0…1) of the way along it.
    pub(crate) fn at(&self, share: f64) -> Point3<f64> {
        self.at_length(share.clamp(0.0, 1.0) * self.length())
    }

    /// The point `s` metres along it.
    pub(crate) fn at_length(&self, s: f64) -> Point3<f64> {
        let i = self
            .run
            .partition_point(|r| *r < s)
            .clamp(1, self.run.len() - 1);
        let (r0, r1) = (self.run[i - 1], self.run[i]);
        let t = if r1 > r0 { (s - r0) / (r1 - r0) } else { 0.0 };
        self.points[i - 1] + (self.points[i] - self.points[i - 1]) * t.clamp(0.0, 1.0)
    }

    /// How far along it (m) its vertex nearest `p` lies.
    pub(crate) fn length_nearest(&self, p: &Point3<f64>) -> f64 {
        let mut best = (f64::INFINITY, 0.0);
        for (q, r) in self.points.iter().zip(&self.run) {
            let d = (q - p).norm_squared();
            if d < best.0 {
                best = (d, *r);
            }
        }
        best.1
    }
}

fn nalgebra_mid(a: &Point3<f64>, b: &Point3<f64>) -> Point3<f64> {
    Point3::from((a.coords + b.coords) / 2.0)
}

/// The unit vector along `v`, or `None` for a vector too short to have a direction.
pub(crate) fn direction(v: &Vector3<f64>) -> Option<Vector3<f64>> {
    let n = v.norm();
    (n > 1e-9).then(|| v / n)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_head::Ellipsoid;

    #[test]
    fn a_sphere_s_great_half_circle_is_pi_r_long_and_passes_through_the_pole() {
        let r = 0.09;
        let s = Ellipsoid::new(
            mocomp_geom::nalgebra::Isometry3::identity(),
            Vector3::new(r, r, r),
        )
        .unwrap();
        let c = Section::new(
            &s,
            &Point3::new(0.0, r, 0.0),
            &Point3::new(0.0, -r, 0.0),
            &Point3::new(0.0, 0.0, 2.0 * r),
            ("a", "b"),
        )
        .unwrap();
        assert!((c.length() - std::f64::consts::PI * r).abs() < 1e-5 * r);
        assert!((c.at(0.5) - Point3::new(0.0, 0.0, r)).norm() < 1e-6);
        let q = c.at(0.25);
        assert!((q.coords.norm() - r).abs() < 1e-4 && q.x.abs() < 1e-9 && q.y > 0.0 && q.z > 0.0);
        assert!((c.length_nearest(&Point3::new(0.0, 0.0, r)) - c.length() / 2.0).abs() < 1e-3);
    }

    #[test]
    fn a_plane_on_the_chord_s_line_is_refused() {
        let s = Ellipsoid::adult();
        let e = Section::new(
            &s,
            &Point3::new(0.0, 0.08, 0.0),
            &Point3::new(0.0, -0.08, 0.0),
            &Point3::new(0.0, 0.02, 0.0),
            ("nasion", "inion"),
        )
        .unwrap_err();
        assert!(matches!(e, NavError::SectionDegenerate { .. }), "{e}");
    }
}
