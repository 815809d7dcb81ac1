//! A target in the image turned into the coil's pose over it, in SimNIBS's convention: the coil
//! frame's origin at the centre of its face, +z into the head along the scalp's inward normal,
//! +y pointing *away from* the handle, x = y × z. (SimNIBS's axes figure,
//! `docs/data/coil_axesorientation.pdf`, has the handle at −y, and so has its Magstim D70
//! casing: its handle's root reaches y = −79 mm, its other side +60 mm.)
//!
//! The coil goes over the **scalp point nearest the target** (what SimNIBS and InVesalius do):
//! for a brain target that is the shortest way in, the least coil-to-target distance. (The
//! point where the target's own normal line leaves the head is not used: inside the brain the
//! scalp's normal is not defined, and on a folded cortex the line can leave far from the nearest
//! scalp.) The face stands `standoff` off that point. Where the scalp curves inward under the
//! coil (beside an ear, under the brow) the face cannot lie flat at that distance: the coil is
//! lifted along the normal until its nearest point is `standoff` off, and a lift beyond
//! [`MAX_LIFT_M`] is refused, naming the nearest scalp point where the coil does fit.

use crate::NavError;
use crate::section::direction;
use mocomp_geom::nalgebra::{
    Isometry3, Point3, Rotation3, Translation3, Unit, UnitQuaternion, Vector3,
};
use mocomp_head::{CoilSolid, HeadShape};

/// The most the coil may be lifted off its place to clear the scalp around it, m: more, and the
/// field at the target weakens for want of a closer coil.
pub const MAX_LIFT_M: f64 = 0.005;

/// How far outside the scalp a target may lie and still be taken as on it, m.
pub const ON_SCALP_M: f64 = 0.002;

/// The farthest from the target the nearest fitting place is looked for, m.
const SEARCH_M: f64 = 0.06;

/// Which way the handle points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Handle {
    /// A direction in the image's frame the handle points along, projected onto the scalp's
    /// tangent plane (posterior, (0, −1, 0), unless told).
    pub toward: Vector3<f64>,
    /// Then turned about the coil's axis by this, rad (positive: counter-clockwise seen from
    /// outside the head).
    pub turn_rad: f64,
}

impl Default for Handle {
    fn default() -> Self {
        Self {
            toward: -Vector3::y(),
            turn_rad: 0.0,
        }
    }
}

/// Where the coil goes for a target, and why there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoilPlacement {
    /// The coil in the image's frame (SimNIBS's convention; metres).
    pub image_from_coil: Isometry3<f64>,
    /// The scalp point under the coil's centre.
    pub scalp_point: Point3<f64>,
    /// The target's depth below that point (0 for a target on the scalp), m.
    pub depth_m: f64,
    /// How far the coil was lifted beyond `standoff` to clear the scalp around it, m.
    pub lift_m: f64,
}

/// The coil's pose for `target` (image frame) under `scalp` (image frame): its face `standoff_m`
/// off the nearest scalp point, lifted to clear the scalp around it.
pub fn place_coil(
    scalp: &dyn HeadShape,
    coil: &CoilSolid,
    target: &Point3<f64>,
    standoff_m: f64,
    handle: &Handle,
) -> Result<CoilPlacement, NavError> {
    if !target.coords.iter().all(|c| c.is_finite()) {
        return Err(NavError::LandmarkNotFinite {
            name: "target".into(),
        });
    }
    let near = scalp.nearest(target);
    if near.signed_distance > ON_SCALP_M {
        return Err(NavError::TargetOutsideHead {
            distance_m: near.signed_distance,
        });
    }
    let placed = over(scalp, coil, &near.point, standoff_m, handle)?;
    if placed.lift_m <= MAX_LIFT_M {
        return Ok(CoilPlacement {
            depth_m: (-near.signed_distance).max(0.0),
            ..placed
        });
    }
    Err(NavError::NoCoilFits {
        lift_m: placed.lift_m,
        limit_m: MAX_LIFT_M,
        nearest_fit: nearest_fit(scalp, coil, &near.point, standoff_m, handle)
            .map(|p| (p.scalp_point, (p.scalp_point - near.point).norm())),
    })
}

/// The coil over the scalp point `at`, lifted as it needs.
pub(crate) fn over(
    scalp: &dyn HeadShape,
    coil: &CoilSolid,
    at: &Point3<f64>,
    standoff_m: f64,
    handle: &Handle,
) -> Result<CoilPlacement, NavError> {
    let normal = scalp.nearest(at).normal.into_inner();
    let z = -normal;
    let along = handle.toward - z * handle.toward.dot(&z);
    let toward = direction(&along).ok_or(NavError::HandleAlongNormal)?;
    let handle_dir =
        UnitQuaternion::from_axis_angle(&Unit::new_unchecked(normal), handle.turn_rad) * toward;
    // SimNIBS's +y points away from the handle.
    let y = -handle_dir;
    let x = y.cross(&z);
    let rotation =
        UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[x, y, z]));
    let pose = |lift: f64| {
        Isometry3::from_parts(
            Translation3::from(at.coords + normal * (standoff_m + lift)),
            rotation,
        )
    };
    // The clearance grows about one for one with the lift where the face is what is nearest;
    // a few rounds settle it.
    let mut lift = 0.0;
    for _ in 0..8 {
        let short = standoff_m - scalp.coil_clearance(&pose(lift), coil);
        if short <= 1e-5 {
            break;
        }
        lift += short;
    }
    Ok(CoilPlacement {
        image_from_coil: pose(lift),
        scalp_point: *at,
        depth_m: 0.0,
        lift_m: lift,
    })
}

/// The nearest scalp point to `at` (rings every 5 mm, 16 directions) where the coil needs no
/// more than [`MAX_LIFT_M`] of lift.
fn nearest_fit(
    scalp: &dyn HeadShape,
    coil: &CoilSolid,
    at: &Point3<f64>,
    standoff_m: f64,
    handle: &Handle,
) -> Option<CoilPlacement> {
    let n = scalp.nearest(at).normal.into_inner();
    let u = direction(&n.cross(&Vector3::x())).or_else(|| direction(&n.cross(&Vector3::y())))?;
    let v = n.cross(&u);
    let rings = (SEARCH_M / 0.005) as usize;
    (1..=rings).find_map(|ring| {
        let r = 0.005 * ring as f64;
        (0..16)
            .filter_map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 16.0;
                let guess = at + (u * a.cos() + v * a.sin()) * r;
                let on = scalp.nearest(&guess).point;
                over(scalp, coil, &on, standoff_m, handle).ok()
            })
            .filter(|p| p.lift_m <= MAX_LIFT_M)
            .min_by(|a, b| {
                let d = |p: &CoilPlacement| (p.scalp_point - at).norm();
                d(a).total_cmp(&d(b))
            })
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_head::Ellipsoid;

    fn coil() -> CoilSolid {
        CoilSolid::new(0.04, 0.02).unwrap()
    }

    #[test]
    fn a_deep_target_gets_the_coil_over_the_nearest_scalp_z_in_y_away_from_the_handle() {
        let head = Ellipsoid::adult();
        let target = Point3::new(-0.03, 0.0, 0.06);
        let p = place_coil(&head, &coil(), &target, 0.004, &Handle::default()).unwrap();
        let r = p.image_from_coil.rotation;
        let (x, y, z) = (r * Vector3::x(), r * Vector3::y(), r * Vector3::z());
        let near = head.nearest(&target);
        assert!((p.scalp_point - near.point).norm() < 1e-12);
        assert!((p.depth_m + near.signed_distance).abs() < 1e-12 && p.depth_m > 0.02);
        assert!(
            z.angle(&-near.normal.into_inner()) < 1e-9,
            "z into the head"
        );
        // The handle posterior: the coil's +y (away from the handle) anterior.
        assert!(y.y > 0.9, "handle posterior, +y anterior: {y}");
        assert!((x - y.cross(&z)).norm() < 1e-12);
        let centre = p.image_from_coil.translation.vector;
        assert!(((centre - p.scalp_point.coords).norm() - 0.004 - p.lift_m).abs() < 1e-9);
        // On a convex head the face's centre is what is nearest: no lift.
        assert!(p.lift_m < 1e-6, "lift {}", p.lift_m);
        assert!((head.coil_clearance(&p.image_from_coil, &coil()) - 0.004).abs() < 1e-4);
        let turned = Handle {
            turn_rad: std::f64::consts::FRAC_PI_2,
            ..Handle::default()
        };
        let q = place_coil(&head, &coil(), &target, 0.004, &turned).unwrap();
        let yq = q.image_from_coil.rotation * Vector3::y();
        assert!((yq.angle(&y) - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    }

    #[test]
    fn a_target_outside_or_a_handle_along_the_normal_is_refused() {
        let head = Ellipsoid::adult();
        let e = place_coil(
            &head,
            &coil(),
            &Point3::new(0.0, 0.0, 0.2),
            0.004,
            &Handle::default(),
        )
        .unwrap_err();
        assert!(matches!(e, NavError::TargetOutsideHead { .. }), "{e}");
        let up = Handle {
            toward: Vector3::z(),
            turn_rad: 0.0,
        };
        let e = place_coil(&head, &coil(), &Point3::new(0.0, 0.0, 0.09), 0.004, &up).unwrap_err();
        assert_eq!(e, NavError::HandleAlongNormal);
    }

    /// A head with a trough: the ellipsoid with a ridge (a second, offset ellipsoid) beside the
    /// target, so a flat coil there must stand off.
    struct Ridged {
        head: Ellipsoid,
        ridge: Ellipsoid,
    }

    impl HeadShape for Ridged {
        fn signed_distance(&self, p: &Point3<f64>) -> f64 {
            self.head
                .signed_distance(p)
                .min(self.ridge.signed_distance(p))
        }
        fn nearest(&self, p: &Point3<f64>) -> mocomp_head::SurfacePoint {
            let (a, b) = (self.head.nearest(p), self.ridge.nearest(p));
            if a.signed_distance <= b.signed_distance {
                a
            } else {
                b
            }
        }
        fn ray_hit(
            &self,
            o: &Point3<f64>,
            d: &Unit<Vector3<f64>>,
            m: f64,
        ) -> Option<mocomp_head::RayHit> {
            let hits = [self.head.ray_hit(o, d, m), self.ridge.ray_hit(o, d, m)];
            hits.into_iter()
                .flatten()
                .min_by(|a, b| a.distance.total_cmp(&b.distance))
        }
        fn bounds(&self) -> mocomp_head::Aabb {
            let (a, b) = (self.head.bounds(), self.ridge.bounds());
            mocomp_head::Aabb {
                min: a.min.inf(&b.min),
                max: a.max.sup(&b.max),
            }
        }
        fn centre(&self) -> Point3<f64> {
            self.head.centre()
        }
        fn radius_along(&self, d: &Vector3<f64>) -> f64 {
            self.head.radius_along(d)
        }
        fn coil_clearance(&self, pose: &Isometry3<f64>, coil: &CoilSolid) -> f64 {
            self.head
                .coil_clearance(pose, coil)
                .min(self.ridge.coil_clearance(pose, coil))
        }
    }

    #[test]
    fn where_the_scalp_rises_beside_the_target_the_coil_lifts_or_the_nearest_fit_is_named() {
        let head = Ellipsoid::adult();
        // A ridge 30 mm to the side of the crown, standing 12 mm proud of it.
        let ridge = Ellipsoid::new(
            Isometry3::translation(0.03, 0.0, 0.11),
            Vector3::new(0.01, 0.03, 0.012),
        )
        .unwrap();
        let ridged = Ridged { head, ridge };
        let crown = Point3::new(0.0, 0.0, 0.1099);
        let e = place_coil(&ridged, &coil(), &crown, 0.004, &Handle::default()).unwrap_err();
        let NavError::NoCoilFits {
            lift_m,
            nearest_fit: Some((fit, away)),
            ..
        } = e
        else {
            panic!("{e}")
        };
        assert!(lift_m > MAX_LIFT_M, "lift {lift_m}");
        assert!(fit.x < 0.0 && away > 0.01, "fit {fit} {away}");
        assert!(e.to_string().contains("nearest"), "{e}");
        let p = place_coil(&ridged, &coil(), &fit, 0.004, &Handle::default()).unwrap();
        assert!(p.lift_m <= MAX_LIFT_M);
        assert!(ridged.coil_clearance(&p.image_from_coil, &coil()) > 0.004 - 1e-4);
    }
}
