//! A head seen from another frame: the same shape, every query carried into its own frame and
//! every answer back. Navigation measures on the scalp in the image's frame (RAS) while the loop
//! holds it in the head marker's; one model serves both.

use crate::shape::{Aabb, CoilSolid, HeadShape, RayHit, SurfacePoint};
use mocomp_geom::nalgebra::{Isometry3, Point3, Unit, Vector3};

/// `shape` (in frame a) answering in frame b.
#[derive(Clone, Copy)]
pub struct Reframed<'a> {
    shape: &'a dyn HeadShape,
    b_from_a: Isometry3<f64>,
}

impl std::fmt::Debug for Reframed<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Reframed")
            .field("b_from_a", &self.b_from_a)
            .finish_non_exhaustive()
    }
}

impl<'a> Reframed<'a> {
    /// `shape`, whose queries are in frame a, seen in frame b.
    pub fn new(shape: &'a dyn HeadShape, b_from_a: Isometry3<f64>) -> Self {
        Self { shape, b_from_a }
    }

    fn a_from_b(&self, p: &Point3<f64>) -> Point3<f64> {
        self.b_from_a.inverse_transform_point(p)
    }
}

impl HeadShape for Reframed<'_> {
    fn signed_distance(&self, p: &Point3<f64>) -> f64 {
        self.shape.signed_distance(&self.a_from_b(p))
    }

    fn nearest(&self, p: &Point3<f64>) -> SurfacePoint {
        let s = self.shape.nearest(&self.a_from_b(p));
        SurfacePoint {
            point: self.b_from_a * s.point,
            normal: self.b_from_a.rotation * s.normal,
            signed_distance: s.signed_distance,
        }
    }

    fn ray_hit(
        &self,
        origin: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_distance: f64,
    ) -> Option<RayHit> {
        let d = self.b_from_a.rotation.inverse() * *direction;
        self.shape
            .ray_hit(&self.a_from_b(origin), &d, max_distance)
            .map(|h| RayHit {
                distance: h.distance,
                point: self.b_from_a * h.point,
                normal: self.b_from_a.rotation * h.normal,
            })
    }

    /// The box around frame a's box's corners, carried into b: it holds the head, if loosely.
    fn bounds(&self) -> Aabb {
        let b = self.shape.bounds();
        let corners: Vec<Point3<f64>> = (0..8)
            .map(|i| {
                let pick = |bit: usize, lo: f64, hi: f64| if i & bit == 0 { lo } else { hi };
                self.b_from_a
                    * Point3::new(
                        pick(1, b.min.x, b.max.x),
                        pick(2, b.min.y, b.max.y),
                        pick(4, b.min.z, b.max.z),
                    )
            })
            .collect();
        Aabb::around(&corners).unwrap_or(b)
    }

    fn centre(&self) -> Point3<f64> {
        self.b_from_a * self.shape.centre()
    }

    fn radius_along(&self, d: &Vector3<f64>) -> f64 {
        self.shape
            .radius_along(&(self.b_from_a.rotation.inverse() * d))
    }

    fn coil_clearance(&self, b_from_coil: &Isometry3<f64>, coil: &CoilSolid) -> f64 {
        self.shape
            .coil_clearance(&(self.b_from_a.inverse() * b_from_coil), coil)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::Ellipsoid;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn every_query_agrees_with_the_shape_built_in_the_other_frame() {
        let radii = Vector3::new(0.07, 0.09, 0.1);
        let b_from_a = Isometry3::from_parts(
            Translation3::new(0.3, -0.2, 0.9),
            UnitQuaternion::from_euler_angles(0.4, -1.1, 2.0),
        );
        let in_a = Ellipsoid::new(Isometry3::identity(), radii).unwrap();
        let in_b = Ellipsoid::new(b_from_a, radii).unwrap();
        let seen = Reframed::new(&in_a, b_from_a);
        let p = b_from_a * Point3::new(0.05, 0.1, 0.02);
        assert!((seen.signed_distance(&p) - in_b.signed_distance(&p)).abs() < 1e-12);
        let (s, t) = (seen.nearest(&p), in_b.nearest(&p));
        assert!((s.point - t.point).norm() < 1e-9 && s.normal.angle(&t.normal) < 1e-9);
        let dir = Unit::new_normalize(b_from_a.translation.vector - p.coords);
        let (h, g) = (
            seen.ray_hit(&p, &dir, 1.0).unwrap(),
            in_b.ray_hit(&p, &dir, 1.0).unwrap(),
        );
        assert!((h.point - g.point).norm() < 1e-9);
        let coil = CoilSolid::new(0.04, 0.02).unwrap();
        let pose = Isometry3::from_parts(Translation3::from(p.coords), UnitQuaternion::identity());
        assert!(
            (seen.coil_clearance(&pose, &coil) - in_b.coil_clearance(&pose, &coil)).abs() < 1e-9
        );
        assert!((seen.centre() - in_b.centre()).norm() < 1e-12);
        let b = seen.bounds();
        assert!(b.distance(&t.point) == 0.0 && b.distance(&seen.centre()) == 0.0);
    }
}
