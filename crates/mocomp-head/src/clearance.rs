//! The coil's exact clearance on a scalp: the least distance between the coil's cylinder and the
//! mesh's triangles, each pair by parry's GJK, as parry's own composite query gives it, for a
//! fraction of the work.
//!
//! parry descends its hierarchy ranking each box by its distance to the cylinder's box in the
//! head frame. A coil tilted over the scalp has a box several centimetres deep, so every
//! triangle under it ranks at zero and thousands go through GJK: a millisecond at 100 k
//! triangles, which is what made the simulated world on a real scalp 3× slower than on the
//! ellipsoid (it measures the coil's true clearance every cycle). Here a box ranks by the
//! greatest of three lower bounds of its distance to the cylinder: parry's, the distance from
//! the box to the slab between the coil's face and back planes (exact for a box, in the coil's
//! own axes), and the distance from the box's enclosing sphere to the cylinder. Under the
//! coil's face the slab's bound is a triangle's distance itself, so only the few triangles
//! nearest the face reach GJK; the search starts from the distance of the coil's nearest sampled
//! point, which any triangle pair must beat. Each bound is one the triangle's true distance
//! cannot be below, so the least found is parry's least (the crate's tests compare them).

use crate::shape::CoilSolid;
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use parry3d_f64::partitioning::BvhNode;
use parry3d_f64::shape::TriMesh;

/// The coil's solid seen from the head: its frame, its axis, the slab it lies in along it and
/// its box.
struct Cylinder<'a> {
    coil: &'a CoilSolid,
    coil_from_head: Isometry3<f64>,
    /// The coil's +z in the head frame (its axis, into the head).
    axis: Vector3<f64>,
    /// The solid's heights along the axis (coil frame z), back to face.
    z_span: (f64, f64),
    /// The solid's box in the head frame: centre and half extents.
    box_centre: Point3<f64>,
    box_half: Vector3<f64>,
}

impl<'a> Cylinder<'a> {
    fn new(coil: &'a CoilSolid, head_from_coil: &Isometry3<f64>) -> Self {
        let axis = head_from_coil.rotation * Vector3::z();
        let (centre, half) = coil.local_box();
        let box_half = match coil.as_cylinder() {
            // A disc of radius r about the axis reaches r·√(1 − aᵢ²) along head axis i; the
            // thickness adds half of itself times |aᵢ|.
            Some((r, t)) => axis.map(|a| r * (1.0 - a * a).max(0.0).sqrt() + 0.5 * t * a.abs()),
            // Any other solid: its own box turned, |R|·h.
            None => head_from_coil.rotation.to_rotation_matrix().matrix().abs() * half,
        };
        Self {
            coil,
            coil_from_head: head_from_coil.inverse(),
            axis,
            z_span: coil.z_span(),
            box_centre: head_from_coil * centre,
            box_half,
        }
    }

    /// How far the span `[lo, hi]` of heights along the axis (coil frame z) is from the slab
    /// the solid lies in.
    fn slab_gap(&self, lo: f64, hi: f64) -> f64 {
        (lo - self.z_span.1).max(self.z_span.0 - hi).max(0.0)
    }

    /// A lower bound of the distance from anything in the box `[min, max]` (head frame) to the
    /// solid.
    fn box_bound(&self, min: &Point3<f64>, max: &Point3<f64>) -> f64 {
        let centre = mocomp_geom::nalgebra::center(min, max);
        let half = (max - min) / 2.0;
        // parry's: the gap between the two boxes.
        let gap = ((centre - self.box_centre).abs() - half - self.box_half)
            .sup(&Vector3::zeros())
            .norm();
        // The slab's: the box's heights along the axis span its centre's ± Σ|aᵢ|·hᵢ.
        let c = self.coil_from_head * centre;
        let spread = self.axis.abs().dot(&half);
        let slab = self.slab_gap(c.z - spread, c.z + spread);
        // The enclosing sphere's.
        let sphere = self.coil.point_distance(&c) - half.norm();
        gap.max(slab).max(sphere)
    }

    /// A lower bound of the distance from the triangle `abc` (head frame) to the solid: the
    /// slab's, exact for a triangle (its heights are its corners').
    fn triangle_bound(&self, abc: [&Point3<f64>; 3]) -> f64 {
        let z = abc.map(|p| (self.coil_from_head * p).z);
        self.slab_gap(z[0].min(z[1]).min(z[2]), z[0].max(z[1]).max(z[2]))
    }
}

/// The least distance between the coil at `head_from_coil` and `mesh`'s triangles, when it is
/// below `at_most` (the distance of some point of the coil to the surface, which bounds it);
/// `None` when no triangle is nearer than that (the caller's bound was not one).
pub(crate) fn least_distance(
    mesh: &TriMesh,
    coil: &CoilSolid,
    head_from_coil: &Isometry3<f64>,
    at_most: f64,
) -> Option<f64> {
    let cylinder = Cylinder::new(coil, head_from_coil);
    let convex = coil.convex();
    let head_from_shape = convex.placed(head_from_coil);
    let shape = convex.shape();
    let vertices = mesh.vertices();
    let indices = mesh.indices();
    // A hair above the bound, so that the triangle it was measured to is still found.
    let limit = at_most + 1e-9 + at_most.abs() * 1e-9;
    mesh.bvh()
        .find_best(
            limit,
            |node: &BvhNode, _| cylinder.box_bound(&node.mins(), &node.maxs()),
            |t, best| {
                let [a, b, c] = indices.get(t as usize)?.map(|i| &vertices[i as usize]);
                if cylinder.triangle_bound([a, b, c]) >= best {
                    return None;
                }
                // The very call parry's composite query makes for each of its triangles.
                parry3d_f64::query::distance(
                    &Isometry3::identity(),
                    &mesh.triangle(t),
                    &head_from_shape,
                    shape,
                )
                .ok()
            },
        )
        .map(|(_, d)| d)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};

    /// The distance from `p` (coil frame) to the solid, exactly.
    fn exact(coil: &CoilSolid, p: &Point3<f64>) -> f64 {
        use parry3d_f64::query::PointQuery;
        match coil.as_casing() {
            Some(c) => c.hull().distance_to_local_point(p, true),
            None => coil.point_distance(p),
        }
    }

    /// Each bound is below the true distance for points of the box or triangle: checked on
    /// random points against the solid's exact point distance, for a cylinder and a casing.
    #[test]
    fn the_bounds_never_exceed_a_distance_they_bound() {
        let casing =
            crate::casing::Casing::new(&crate::casing::tests::slab().vertices, "slab").unwrap();
        for coil in [
            CoilSolid::new(0.04, 0.03).unwrap(),
            CoilSolid::casing(std::sync::Arc::new(casing)),
        ] {
            bounds_never_exceed_a_distance(&coil);
        }
    }

    fn bounds_never_exceed_a_distance(coil: &CoilSolid) {
        let mut s = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..2000 {
            let pose = Isometry3::from_parts(
                Translation3::new(next() * 0.2 - 0.1, next() * 0.2 - 0.1, next() * 0.2 - 0.1),
                UnitQuaternion::from_euler_angles(next() * 6.3, next() * 6.3, next() * 6.3),
            );
            let cyl = Cylinder::new(coil, &pose);
            let min = Point3::new(next() * 0.2 - 0.1, next() * 0.2 - 0.1, next() * 0.2 - 0.1);
            let max = min + Vector3::new(next(), next(), next()) * 0.05;
            let bound = cyl.box_bound(&min, &max);
            let tri = [0, 1, 2]
                .map(|_| min + (max - min).component_mul(&Vector3::new(next(), next(), next())));
            let tbound = cyl.triangle_bound([&tri[0], &tri[1], &tri[2]]);
            for _ in 0..50 {
                let p = min + (max - min).component_mul(&Vector3::new(next(), next(), next()));
                let d = exact(coil, &(cyl.coil_from_head * p));
                assert!(bound <= d + 1e-12, "box bound {bound} above {d}");
                let (u, v) = (next(), next());
                let (u, v) = if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                };
                let q = tri[0] + (tri[1] - tri[0]) * u + (tri[2] - tri[0]) * v;
                let dq = exact(coil, &(cyl.coil_from_head * q));
                assert!(tbound <= dq + 1e-12, "triangle bound {tbound} above {dq}");
            }
        }
    }

    /// The cylinder's box holds the cylinder: its rim and faces lie inside.
    #[test]
    fn the_cylinders_box_holds_it() {
        let coil = CoilSolid::new(0.04, 0.03).unwrap();
        let pose = Isometry3::from_parts(
            Translation3::new(0.01, -0.02, 0.1),
            UnitQuaternion::from_euler_angles(0.4, -1.1, 2.0),
        );
        let cyl = Cylinder::new(&coil, &pose);
        for k in 0..360 {
            let a = (k as f64).to_radians();
            for z in [0.0, -0.03] {
                let p = pose * Point3::new(0.04 * a.cos(), 0.04 * a.sin(), z);
                let off = (p - cyl.box_centre).abs() - cyl.box_half;
                assert!(off.max() <= 1e-12, "{p}: {off}");
            }
        }
    }
}
