//! The head as an ellipsoid: the model mocomp began with, kept for a patient without a scan and
//! as the fitted comparison for one with.

use crate::error::HeadError;
use crate::shape::{Aabb, CoilSolid, HeadShape, RayHit, SurfacePoint};
use mocomp_geom::nalgebra::{Isometry3, Point3, Unit, Vector3};
use parry3d_f64::query::details::distance_support_map_support_map;
use parry3d_f64::shape::SupportMap;

/// An ellipsoid in the head (marker) frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    head_from_ellipsoid: Isometry3<f64>,
    radii: Vector3<f64>,
}

impl Ellipsoid {
    /// The ellipsoid with semi-axes `radii` (m) about the axes of `head_from_ellipsoid`.
    pub fn new(
        head_from_ellipsoid: Isometry3<f64>,
        radii: Vector3<f64>,
    ) -> Result<Self, HeadError> {
        if radii.iter().all(|r| r.is_finite() && *r > 0.0) {
            Ok(Self {
                head_from_ellipsoid,
                radii,
            })
        } else {
            Err(HeadError::BadRadii {
                radii: [radii.x, radii.y, radii.z],
            })
        }
    }

    /// The adult head mocomp assumes without a scan: semi-axes 75, 95 and 110 mm (x left-right,
    /// y front-back, z up) about the head frame's origin.
    pub fn adult() -> Self {
        Self {
            head_from_ellipsoid: Isometry3::identity(),
            radii: Vector3::new(0.075, 0.095, 0.11),
        }
    }

    /// The ellipsoid, axes along the head frame's, that best fits `points` (a scalp's vertices):
    /// the algebraic least-squares fit `a x² + b y² + c z² + d x + e y + f z = 1`, what a head
    /// model without a scan would be measured as. Refused when the points close no ellipsoid.
    pub fn fit(points: &[Point3<f64>]) -> Result<Self, HeadError> {
        let no = |why| HeadError::NoFit {
            points: points.len(),
            why,
        };
        if points.len() < 6 {
            return Err(no("six are the least"));
        }
        // Centred and scaled first, so the normal equations are well conditioned.
        let n = points.len() as f64;
        let mean = points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n;
        let scale = points
            .iter()
            .map(|p| (p.coords - mean).norm())
            .fold(0.0, f64::max)
            .max(1e-12);
        let mut ata = mocomp_geom::nalgebra::Matrix6::<f64>::zeros();
        let mut atb = mocomp_geom::nalgebra::Vector6::<f64>::zeros();
        for p in points {
            let q = (p.coords - mean) / scale;
            let row =
                mocomp_geom::nalgebra::Vector6::new(q.x * q.x, q.y * q.y, q.z * q.z, q.x, q.y, q.z);
            ata += row * row.transpose();
            atb += row;
        }
        let k = ata
            .cholesky()
            .ok_or_else(|| no("they lie on a plane or a line"))?
            .solve(&atb);
        let (a, b, c) = (k[0], k[1], k[2]);
        if !(a > 0.0 && b > 0.0 && c > 0.0) {
            return Err(no("they curve away from each other (not a closed surface)"));
        }
        // a (x - x0)² + … = 1 + a x0² + …, x0 = -d / 2a.
        let centre = Vector3::new(-k[3] / (2.0 * a), -k[4] / (2.0 * b), -k[5] / (2.0 * c));
        let rhs = 1.0 + a * centre.x.powi(2) + b * centre.y.powi(2) + c * centre.z.powi(2);
        let radii = Vector3::new((rhs / a).sqrt(), (rhs / b).sqrt(), (rhs / c).sqrt()) * scale;
        let c = mean + centre * scale;
        Self::new(Isometry3::translation(c.x, c.y, c.z), radii)
    }

    /// Its centre and axes in the head frame.
    pub fn head_from_ellipsoid(&self) -> &Isometry3<f64> {
        &self.head_from_ellipsoid
    }

    /// Its semi-axes, m.
    pub fn radii(&self) -> &Vector3<f64> {
        &self.radii
    }

    /// The outward normal at `y` on the surface, ellipsoid frame.
    fn normal_at(&self, y: &Vector3<f64>) -> Unit<Vector3<f64>> {
        let r = &self.radii;
        let g = Vector3::new(y.x / (r.x * r.x), y.y / (r.y * r.y), y.z / (r.z * r.z));
        Unit::try_new(g, 1e-300).unwrap_or(Vector3::z_axis())
    }
}

/// Distance from `p` (ellipsoid frame) to the ellipsoid with semi-axes `r`: exact outside; inside,
/// `-(1 - √s)·r_min` (s the point's ellipsoid "radius"), a lower bound of the depth that needs no
/// solve. The control loop's check.
pub fn ellipsoid_distance(p: &Vector3<f64>, r: &Vector3<f64>) -> f64 {
    let s = (p.x / r.x).powi(2) + (p.y / r.y).powi(2) + (p.z / r.z).powi(2);
    let rmin = r.x.min(r.y).min(r.z);
    if s <= 1.0 {
        return -(1.0 - s.sqrt()) * rmin;
    }
    (p - closest_outside(p, r)).norm()
}

/// The closest surface point to `p` outside: y_i = r_i² p_i / (t + r_i²), with t ≥ 0 the root
/// of f(t) = Σ (r_i p_i / (t + r_i²))² − 1, decreasing and convex, so Newton from t = 0
/// converges monotonically.
fn closest_outside(p: &Vector3<f64>, r: &Vector3<f64>) -> Vector3<f64> {
    let a = [r.x * r.x, r.y * r.y, r.z * r.z];
    let q = [p.x, p.y, p.z];
    let mut t = 0.0;
    for _ in 0..40 {
        let mut f = -1.0;
        let mut df = 0.0;
        for i in 0..3 {
            let u = r[i] * q[i] / (t + a[i]);
            f += u * u;
            df += -2.0 * u * u / (t + a[i]);
        }
        if f.abs() < 1e-14 || df == 0.0 {
            break;
        }
        t -= f / df;
    }
    Vector3::new(
        a[0] * q[0] / (t + a[0]),
        a[1] * q[1] / (t + a[1]),
        a[2] * q[2] / (t + a[2]),
    )
}

/// The closest surface point to `p` inside. The same stationarity, with t in (−r_min², 0): f
/// rises to +∞ at the pole, so bisection on the bracket is safe. When p lies in the plane of the
/// shortest axis the pole vanishes and, if f stays negative, the nearest points leave that plane
/// (two of them, mirror images): take the one on p's side, or +.
fn closest_inside(p: &Vector3<f64>, r: &Vector3<f64>) -> Vector3<f64> {
    let k = (0..3).min_by(|&i, &j| r[i].total_cmp(&r[j])).unwrap_or(2);
    let a = [r.x * r.x, r.y * r.y, r.z * r.z];
    let f = |t: f64| -> f64 {
        (0..3)
            .map(|i| (r[i] * p[i] / (t + a[i])).powi(2))
            .sum::<f64>()
            - 1.0
    };
    let lo0 = -a[k];
    // Nearly on the pole: f near lo is +∞ only if p_k ≠ 0.
    let eps = a[k] * 1e-12;
    if f(lo0 + eps) > 0.0 {
        let (mut lo, mut hi) = (lo0 + eps, 0.0);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if f(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-15 * a[k] {
                break;
            }
        }
        let t = 0.5 * (lo + hi);
        return Vector3::from_fn(|i, _| a[i] * p[i] / (t + a[i]));
    }
    let mut y = Vector3::zeros();
    let mut s = 0.0;
    for i in (0..3).filter(|&i| i != k) {
        let d = a[i] - a[k];
        y[i] = if d > 0.0 { a[i] * p[i] / d } else { 0.0 };
        s += (y[i] / r[i]).powi(2);
    }
    let side = if p[k] < 0.0 { -1.0 } else { 1.0 };
    y[k] = side * r[k] * (1.0 - s).max(0.0).sqrt();
    y
}

/// The ellipsoid as GJK sees it (its own frame).
struct Support<'a>(&'a Vector3<f64>);

impl SupportMap for Support<'_> {
    fn local_support_point(&self, dir: &Vector3<f64>) -> Point3<f64> {
        let r = self.0;
        let rd = r.component_mul(dir);
        let n = rd.norm();
        if n == 0.0 {
            return Point3::origin();
        }
        Point3::from(r.component_mul(&rd) / n)
    }
}

impl Ellipsoid {
    /// The coil's clearance as the control loop takes it: a casing exactly (GJK on its hull,
    /// spared where its bounding sphere is far enough); a cylinder as the nearest of its face's
    /// and back's centres and rims (a convex head meets a coil facing it there first), each by
    /// [`HeadShape::distance_below`]. Where it is at least `cutoff`, any value of at least
    /// `cutoff`.
    pub fn loop_clearance_below(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
    ) -> f64 {
        let Some((r, t)) = coil.as_cylinder() else {
            return self.coil_clearance_below(head_from_coil, coil, cutoff);
        };
        // Unit offsets, no trigonometry per call: this runs several times a control cycle.
        let mut nearest = f64::INFINITY;
        for z in [0.0, -t] {
            for (c, s) in crate::shape::COIL_RIM {
                let p = Point3::new(r * c, r * s, z);
                nearest = nearest.min(self.distance_below(&(head_from_coil * p), cutoff));
            }
        }
        nearest
    }
}

impl HeadShape for Ellipsoid {
    /// Where the bounding sphere is at least `cutoff` away, its distance (no solve); else
    /// [`ellipsoid_distance`]: exact outside, and inside the cheap lower bound of the depth the
    /// loop has always taken (any depth there is a violation it acts on).
    fn distance_below(&self, p: &Point3<f64>, cutoff: f64) -> f64 {
        let q = self.head_from_ellipsoid.inverse_transform_point(p).coords;
        let bound = q.norm() - self.radii.max();
        if bound >= cutoff {
            bound
        } else {
            ellipsoid_distance(&q, &self.radii)
        }
    }

    fn signed_distance(&self, p: &Point3<f64>) -> f64 {
        let q = self.head_from_ellipsoid.inverse_transform_point(p).coords;
        let d = ellipsoid_distance(&q, &self.radii);
        if d > 0.0 {
            d
        } else {
            // Inside (rare: a violation), the exact depth.
            -(q - closest_inside(&q, &self.radii)).norm()
        }
    }

    fn nearest(&self, p: &Point3<f64>) -> SurfacePoint {
        let q = self.head_from_ellipsoid.inverse_transform_point(p).coords;
        let r = &self.radii;
        let s = (q.x / r.x).powi(2) + (q.y / r.y).powi(2) + (q.z / r.z).powi(2);
        let (y, sign) = if s > 1.0 {
            (closest_outside(&q, r), 1.0)
        } else {
            (closest_inside(&q, r), -1.0)
        };
        let normal = self.normal_at(&y);
        SurfacePoint {
            point: self.head_from_ellipsoid * Point3::from(y),
            normal: self.head_from_ellipsoid.rotation * normal,
            signed_distance: sign * (q - y).norm(),
        }
    }

    fn ray_hit(
        &self,
        origin: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_distance: f64,
    ) -> Option<RayHit> {
        // In the frame where the ellipsoid is the unit sphere the ray is o' + t d', with t the
        // same parameter: |o' + t d'|² = 1.
        let o = self
            .head_from_ellipsoid
            .inverse_transform_point(origin)
            .coords;
        let d = self.head_from_ellipsoid.inverse_transform_vector(direction);
        let o1 = o.component_div(&self.radii);
        let d1 = d.component_div(&self.radii);
        let (a, b, c) = (d1.dot(&d1), 2.0 * o1.dot(&d1), o1.dot(&o1) - 1.0);
        let disc = b * b - 4.0 * a * c;
        if disc < 0.0 || a == 0.0 {
            return None;
        }
        let sq = disc.sqrt();
        let (t0, t1) = ((-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a));
        let t = if t0 >= 0.0 { t0 } else { t1 };
        if !(0.0..=max_distance).contains(&t) {
            return None;
        }
        let y = o + d * t;
        Some(RayHit {
            distance: t,
            point: self.head_from_ellipsoid * Point3::from(y),
            normal: self.head_from_ellipsoid.rotation * self.normal_at(&y),
        })
    }

    fn bounds(&self) -> Aabb {
        // Each world axis's half extent: √Σ_j (R_ij r_j)².
        let m = self.head_from_ellipsoid.rotation.to_rotation_matrix();
        let half = Vector3::from_fn(|i, _| {
            (0..3)
                .map(|j| (m[(i, j)] * self.radii[j]).powi(2))
                .sum::<f64>()
                .sqrt()
        });
        let c = Point3::from(self.head_from_ellipsoid.translation.vector);
        Aabb {
            min: c - half,
            max: c + half,
        }
    }

    fn centre(&self) -> Point3<f64> {
        Point3::from(self.head_from_ellipsoid.translation.vector)
    }

    fn radius_along(&self, d: &Vector3<f64>) -> f64 {
        let d = self.head_from_ellipsoid.inverse_transform_vector(d);
        1.0 / d.component_div(&self.radii).norm()
    }

    fn coil_clearance(&self, head_from_coil: &Isometry3<f64>, coil: &CoilSolid) -> f64 {
        let convex = coil.convex();
        let ellipsoid_from_shape = self
            .head_from_ellipsoid
            .inv_mul(&convex.placed(head_from_coil));
        let d = distance_support_map_support_map(
            &ellipsoid_from_shape,
            &Support(&self.radii),
            convex.support(),
        );
        if d > 0.0 {
            return d;
        }
        // Cutting in: as deep as its deepest face or rim point, as for the mesh.
        coil.key_points(head_from_coil)
            .map(|p| self.signed_distance(&p))
            .fold(0.0, f64::min)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use proptest::prelude::*;

    fn head() -> Ellipsoid {
        Ellipsoid::new(
            Isometry3::new(
                Vector3::new(0.01, -0.02, 0.005),
                Vector3::new(0.1, 0.2, -0.3),
            ),
            Vector3::new(0.075, 0.095, 0.11),
        )
        .unwrap()
    }

    fn on_surface(e: &Ellipsoid, p: &Point3<f64>) -> f64 {
        let q = e.head_from_ellipsoid.inverse_transform_point(p).coords;
        let r = e.radii;
        (q.x / r.x).powi(2) + (q.y / r.y).powi(2) + (q.z / r.z).powi(2)
    }

    proptest! {
        /// The nearest point is on the surface, the query point lies along its normal from it,
        /// and no other surface point (sampled) is nearer.
        #[test]
        fn the_nearest_point_is_on_the_surface_along_its_normal(
            x in -0.3..0.3f64, y in -0.3..0.3f64, z in -0.3..0.3f64,
        ) {
            let e = head();
            let p = Point3::new(x, y, z);
            let n = e.nearest(&p);
            prop_assert!((on_surface(&e, &n.point) - 1.0).abs() < 1e-9);
            let off = p - n.point;
            prop_assert!((off.norm() - n.signed_distance.abs()).abs() < 1e-12);
            if off.norm() > 1e-6 {
                prop_assert!(off.normalize().cross(&n.normal).norm() < 1e-6);
                prop_assert_eq!(off.dot(&n.normal) > 0.0, n.signed_distance > 0.0);
            }
            for i in 0..200 {
                let th = i as f64 * 0.7;
                let ph = (i as f64 * 0.377).sin() * 1.5;
                let s = e.head_from_ellipsoid * Point3::new(
                    e.radii.x * ph.cos() * th.cos(), e.radii.y * ph.cos() * th.sin(), e.radii.z * ph.sin());
                prop_assert!((s - p).norm() >= n.signed_distance.abs() - 1e-9);
            }
            prop_assert!((e.signed_distance(&p) - n.signed_distance).abs() < 1e-9);
            // The cheap inside figure is a lower bound of the depth.
            let q = e.head_from_ellipsoid.inverse_transform_point(&p).coords;
            let cheap = ellipsoid_distance(&q, &e.radii);
            prop_assert!(cheap >= n.signed_distance - 1e-12);
        }

        /// A ray through the centre hits the surface where the surface is, and its normal
        /// faces back along the ray.
        #[test]
        fn a_ray_at_the_centre_hits_the_surface(
            x in -0.5..0.5f64, y in -0.5..0.5f64, z in 0.2..0.5f64,
        ) {
            let e = head();
            let o = Point3::new(x, y, z);
            let c = Point3::from(e.head_from_ellipsoid.translation.vector);
            let d = Unit::new_normalize(c - o);
            let hit = e.ray_hit(&o, &d, 10.0).unwrap();
            prop_assert!((on_surface(&e, &hit.point) - 1.0).abs() < 1e-9);
            prop_assert!(hit.normal.dot(&d) < 0.0);
            prop_assert!(e.ray_hit(&o, &-d, 10.0).is_none());
        }
    }

    #[test]
    fn an_ellipsoid_fitted_to_points_on_one_is_that_one() {
        let truth = Ellipsoid::new(
            Isometry3::translation(0.01, -0.02, 0.03),
            Vector3::new(0.075, 0.095, 0.11),
        )
        .unwrap();
        let mut points = Vec::new();
        for i in 0..30 {
            for j in 0..60 {
                let th = std::f64::consts::PI * (f64::from(i) + 0.5) / 30.0;
                let ph = std::f64::consts::TAU * f64::from(j) / 60.0;
                let u = Vector3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
                points.push(Point3::from(
                    Vector3::new(0.01, -0.02, 0.03) + u.component_mul(truth.radii()),
                ));
            }
        }
        let fit = Ellipsoid::fit(&points).unwrap();
        assert!(
            (fit.radii() - truth.radii()).norm() < 1e-9,
            "{}",
            fit.radii()
        );
        assert!((fit.centre() - truth.centre()).norm() < 1e-9);
        // A plane closes no ellipsoid; five points are too few.
        let flat: Vec<_> = points.iter().map(|p| Point3::new(p.x, p.y, 0.0)).collect();
        assert!(matches!(
            Ellipsoid::fit(&flat),
            Err(HeadError::NoFit { .. })
        ));
        assert!(matches!(
            Ellipsoid::fit(&points[..5]),
            Err(HeadError::NoFit { .. })
        ));
    }

    #[test]
    fn the_box_holds_the_ellipsoid_and_touches_it() {
        let e = head();
        let b = e.bounds();
        let mut touched = [false; 6];
        for i in 0..20_000 {
            let th = i as f64 * 0.0123;
            let ph = (i as f64 * 0.00791).sin() * std::f64::consts::FRAC_PI_2;
            let s = e.head_from_ellipsoid
                * Point3::new(
                    e.radii.x * ph.cos() * th.cos(),
                    e.radii.y * ph.cos() * th.sin(),
                    e.radii.z * ph.sin(),
                );
            assert!(b.distance(&s) == 0.0);
            for k in 0..3 {
                touched[k] |= s[k] - b.min[k] < 1e-3;
                touched[k + 3] |= b.max[k] - s[k] < 1e-3;
            }
        }
        assert!(touched.iter().all(|t| *t), "{touched:?}");
    }

    /// The coil's clearance as a solid: a coil facing the head at 10 mm is 10 mm clear; turned
    /// on its edge, its rim is nearer; pushed in, it is negative.
    #[test]
    fn the_coil_clearance_is_the_solid_s() {
        let e = Ellipsoid::new(Isometry3::identity(), Vector3::new(0.075, 0.095, 0.11)).unwrap();
        let coil = CoilSolid::new(0.04, 0.03).unwrap();
        // Above the vertex, +z of the coil pointing down into the head.
        let facing = Isometry3::new(
            Vector3::new(0.0, 0.0, 0.12),
            Vector3::x() * std::f64::consts::PI,
        );
        let d = e.coil_clearance(&facing, &coil);
        // The face is flat, the head curves away: the face's centre is nearest, 10 mm.
        assert!((d - 0.01).abs() < 1e-6, "{d}");
        // On its edge (axis along x), the rim hangs down to z = 0.12 - 0.04 = 0.08 < 0.11.
        let edge = Isometry3::new(
            Vector3::new(0.0, 0.0, 0.12),
            Vector3::y() * std::f64::consts::FRAC_PI_2,
        );
        assert!(e.coil_clearance(&edge, &coil) < 0.0);
        let pushed = Isometry3::new(
            Vector3::new(0.0, 0.0, 0.105),
            Vector3::x() * std::f64::consts::PI,
        );
        let d = e.coil_clearance(&pushed, &coil);
        // The face's centre is 5 mm in: the deepest point of the coil's surface.
        assert!((d + 0.005).abs() < 1e-9, "{d}");
        // The cheap bound never claims more clearance than there is, and is exact below it.
        for cutoff in [-0.01, 0.0, 0.005, 0.02, 0.5] {
            for pose in [facing, edge, pushed] {
                let exact = e.coil_clearance(&pose, &coil);
                let b = e.coil_clearance_below(&pose, &coil, cutoff);
                if exact < cutoff {
                    assert_eq!(b, exact);
                } else {
                    assert!(b >= cutoff && b <= exact + 1e-12);
                }
            }
        }
    }
}
