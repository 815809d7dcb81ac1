//! The sphere a head is taken to be under the coil: fitted to the scalp within
//! [`FIT_RADIUS_M`] of the point under the coil's centre, as local-sphere methods fit one per
//! coil position (or per MEG sensor).
//!
//! **Why 30 mm.** The field at a target under the coil's centre comes from the windings within
//! about 50 mm of it (a figure-of-eight's wings), and the sphere stands for the scalp's
//! curvature there. A patch of 30 mm radius spans the centre's neighbourhood where the field is
//! strongest and follows the head's change of curvature between forehead, vertex and temple; a
//! much smaller one fits the scalp's bumps and the mesh's facets (its radius then swings by
//! centimetres from one position to the next), a much larger one averages the temple with the
//! vertex. The scalp is sampled, not taken as the mesh's vertices, so that any head shape (the
//! ellipsoid or a scan's mesh, at any density) gives the same patch: a polar grid of points on
//! the scalp's tangent plane, each brought to the scalp's nearest point.

use crate::error::EfieldError;
use crate::fit::fit_sphere;
use crate::sphere::Sphere;
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_head::HeadShape;

/// The patch of scalp the sphere is fitted to: this far from the point under the coil, m.
pub const FIT_RADIUS_M: f64 = 0.03;
/// Rings of the polar grid (the centre, then 6, 12, … points a ring).
const RINGS: usize = 6;
/// How far above the tangent plane each grid point starts before it is brought to the scalp, m:
/// outside the head, so the nearest point is on the side the coil is.
const LIFT_M: f64 = 0.01;

/// A sphere fitted under a coil.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalSphere {
    /// The sphere.
    pub sphere: Sphere,
    /// The scalp point under the coil's centre (the patch's middle), head frame, m.
    pub under_coil: Point3<f64>,
    /// The root-mean-square distance of the patch's points from the sphere, m.
    pub rms_m: f64,
    /// How many scalp points it was fitted to.
    pub points: usize,
}

/// The sphere fitted to `scalp` within `fit_radius` of the scalp point nearest the coil's centre
/// (its frame's origin) at `head_from_coil`.
pub fn local_sphere(
    scalp: &dyn HeadShape,
    head_from_coil: &Isometry3<f64>,
    fit_radius: f64,
) -> Result<LocalSphere, EfieldError> {
    let centre = Point3::from(head_from_coil.translation.vector);
    let under = scalp.nearest(&centre);
    let n = under.normal.into_inner();
    // Two directions across the normal.
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = n.cross(&helper).normalize();
    let v = n.cross(&u);
    let mut points = Vec::with_capacity(1 + 3 * RINGS * (RINGS + 1));
    points.push(under.point);
    for ring in 1..=RINGS {
        let r = fit_radius * ring as f64 / RINGS as f64;
        let count = 6 * ring;
        for k in 0..count {
            let a = std::f64::consts::TAU * (k as f64 + 0.5 * (ring % 2) as f64) / count as f64;
            let q = under.point + (u * a.cos() + v * a.sin()) * r + n * LIFT_M;
            let s = scalp.nearest(&q).point;
            if (s - under.point).norm() <= fit_radius * 1.05 {
                points.push(s);
            }
        }
    }
    let sphere = fit_sphere(&points)?;
    let rms_m = (points
        .iter()
        .map(|p| ((p - sphere.centre).norm() - sphere.radius).powi(2))
        .sum::<f64>()
        / points.len() as f64)
        .sqrt();
    Ok(LocalSphere {
        sphere,
        under_coil: under.point,
        rms_m,
        points: points.len(),
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};
    use mocomp_head::Ellipsoid;

    /// A rotation taking the coil's +z to −`dir` (into the head).
    fn facing(dir: Vector3<f64>) -> UnitQuaternion<f64> {
        UnitQuaternion::rotation_between(&Vector3::z(), &-dir).unwrap_or_else(|| {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        })
    }

    #[test]
    fn on_a_sphere_the_local_sphere_is_the_sphere_and_on_an_ellipsoid_its_curvature() {
        // A sphere as an ellipsoid of equal axes, off the origin; the coil anywhere over it.
        let c = Point3::new(0.01, 0.02, -0.03);
        let ball = Ellipsoid::new(
            Isometry3::translation(c.x, c.y, c.z),
            Vector3::new(0.09, 0.09, 0.09),
        )
        .unwrap();
        for dir in [Vector3::z(), Vector3::new(1.0, 0.3, 0.2).normalize()] {
            let pose =
                Isometry3::from_parts(Translation3::from(c.coords + dir * 0.095), facing(dir));
            let s = local_sphere(&ball, &pose, FIT_RADIUS_M).unwrap();
            assert!((s.sphere.radius - 0.09).abs() < 1e-6, "{s:?}");
            assert!((s.sphere.centre - c).norm() < 1e-6, "{s:?}");
            assert!(s.rms_m < 1e-7 && s.points > 100, "{s:?}");
        }
        // Over the end of an ellipsoid's long axis (a = 0.1, b = c = 0.07) the surface curves
        // with radius b²/a = 49 mm; over the end of a short one with b (across) and a²/b = 143
        // mm (along the long axis): the fit lies between.
        let egg = Ellipsoid::new(Isometry3::identity(), Vector3::new(0.1, 0.07, 0.07)).unwrap();
        let over = |dir: Vector3<f64>, reach: f64| {
            let pose =
                Isometry3::from_parts(Translation3::from(dir * (reach + 0.005)), facing(dir));
            local_sphere(&egg, &pose, FIT_RADIUS_M)
                .unwrap()
                .sphere
                .radius
        };
        let tip = over(Vector3::x(), 0.1);
        let side = over(Vector3::z(), 0.07);
        assert!(tip > 0.045 && tip < 0.06, "{tip}");
        assert!(side > 0.07 && side < 0.143, "{side}");
    }
}
