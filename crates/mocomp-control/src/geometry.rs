//! The collision model: the head (an ellipsoid or the patient's scalp, the head crate's
//! [`Head`]) in the head marker's frame, the coil as points spread over its surface, the arm's
//! links as capsules between DH frames. Distances to the ellipsoid are exact for points outside
//! (Newton on the standard secular equation) and a cheap lower bound of the depth inside; to the
//! scalp, exact through its distance field.

use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_head::casing::Casing;
use mocomp_head::sampled::ClearanceMemory;
use mocomp_head::{CoilSolid, Ellipsoid, Head, HeadError, HeadShape, ScanCut};
use std::sync::Arc;

/// The head the loop keeps the coil from, in the head (marker) frame. Clones share a mesh;
/// two are equal as [`Head`]s are (ellipsoids by their axes, scalps only the same one).
#[derive(Debug, Clone, PartialEq)]
pub struct HeadModel {
    shape: Head,
}

impl HeadModel {
    /// The ellipsoid with semi-axes `radii` (m) about `head_from_ellipsoid`.
    pub fn ellipsoid(
        head_from_ellipsoid: Isometry3<f64>,
        radii: Vector3<f64>,
    ) -> Result<Self, HeadError> {
        Ellipsoid::new(head_from_ellipsoid, radii).map(|e| Self {
            shape: Head::Ellipsoid(e),
        })
    }

    /// The default adult head: semi-axes 75, 95 and 110 mm about the marker's origin.
    pub fn adult() -> Self {
        Self {
            shape: Head::Ellipsoid(Ellipsoid::adult()),
        }
    }

    /// The head `shape` (an ellipsoid, or a scalp mesh read and built at start-up).
    pub fn new(shape: Head) -> Self {
        Self { shape }
    }

    /// The shape, for the questions only it answers (rays, nearest points, the shell's radius).
    pub fn shape(&self) -> &Head {
        &self.shape
    }

    /// The ellipsoid, when the head is one.
    pub fn as_ellipsoid(&self) -> Option<&Ellipsoid> {
        self.shape.as_ellipsoid()
    }

    /// Where the scan the scalp came from ends inside the head (none for an ellipsoid or a
    /// surface read whole): the model is flat there, not the patient.
    pub fn scan_cuts(&self) -> &[ScanCut] {
        self.shape.cuts()
    }

    /// Signed distance (m) from a point in the head frame to the surface: positive outside,
    /// negative inside (inside the ellipsoid: a lower bound of the depth).
    pub fn distance(&self, p_head: &Point3<f64>) -> f64 {
        self.distance_below(p_head, f64::INFINITY)
    }

    /// [`Self::distance`] where it is below `cutoff`; elsewhere a lower bound of it that is at
    /// least `cutoff` (the distance to the ellipsoid's bounding sphere, or to the scalp's box),
    /// which spares the exact solve for the many points a check only needs to know are far
    /// enough.
    pub fn distance_below(&self, p_head: &Point3<f64>, cutoff: f64) -> f64 {
        self.shape.distance_below(p_head, cutoff)
    }
}

/// Distance from `p` (ellipsoid frame) to the ellipsoid with semi-axes `r`: exact outside, a
/// lower bound of the depth inside (the head crate's, which the mesh head sits beside).
pub use mocomp_head::ellipsoid_distance;

/// The coil: a cylinder behind its face (+z of the coil frame points into the head; the coil's
/// face is the origin), or, where one is given, its casing as drawn (SimNIBS's `.stl`, in the
/// same frame: [`mocomp_head::casing::Casing`]), which every clearance then measures in place
/// of the cylinder. Clones share the casing.
#[derive(Debug, Clone, PartialEq)]
pub struct CoilModel {
    /// Coil radius seen from the head, m.
    pub radius: f64,
    /// Coil thickness behind its face (towards the flange), m.
    pub thickness: f64,
    /// The casing, when given: the solid in place of the cylinder.
    pub casing: Option<Arc<Casing>>,
}

impl CoilModel {
    /// A cylinder of `radius` and `thickness`, m.
    pub fn cylinder(radius: f64, thickness: f64) -> Self {
        Self {
            radius,
            thickness,
            casing: None,
        }
    }

    /// The solid the clearances measure: the casing where there is one, else the cylinder
    /// (an error for a cylinder that is none: zero, negative or not finite).
    pub fn solid(&self) -> Result<CoilSolid, HeadError> {
        match &self.casing {
            Some(c) => Ok(CoilSolid::casing(Arc::clone(c))),
            None => CoilSolid::new(self.radius, self.thickness),
        }
    }

    /// The farthest any point of the coil's solid is from its origin, m (a bound of how far a
    /// turn moves it).
    pub fn extent(&self) -> f64 {
        match &self.casing {
            Some(c) => c.extent(),
            None => self.radius.hypot(self.thickness),
        }
    }

    /// Signed distance (m) from the coil at `head_from_coil` to `head`; negative when inside the
    /// head, as the loop measures it ([`Head::loop_clearance_below`]): the cylinder against the
    /// ellipsoid by its face's and back's centres and rims, a casing against it exactly (GJK),
    /// against a scalp the nearest of points every few millimetres over the solid's surface,
    /// less what the scalp may bulge between them: never more room than there is.
    pub fn distance(&self, head: &HeadModel, head_from_coil: &Isometry3<f64>) -> f64 {
        self.distance_below(head, head_from_coil, f64::INFINITY)
    }

    /// The distance a report measures the true coil by ([`Head::reported_clearance`]): against
    /// a scalp exact, against the ellipsoid [`Self::distance`].
    pub fn measured_distance(&self, head: &HeadModel, head_from_coil: &Isometry3<f64>) -> f64 {
        self.solid().map_or(f64::NEG_INFINITY, |solid| {
            head.shape.reported_clearance(head_from_coil, &solid)
        })
    }

    /// [`Self::distance`] where it is below `cutoff`; elsewhere some value of at least `cutoff`
    /// (see [`HeadModel::distance_below`]).
    pub fn distance_below(
        &self,
        head: &HeadModel,
        head_from_coil: &Isometry3<f64>,
        cutoff: f64,
    ) -> f64 {
        self.distance_below_in(head, head_from_coil, cutoff, None)
    }

    /// [`Self::distance_below`], the same value, sparing on a scalp the samples that `memory`
    /// (this call site's, from its last call) shows cannot be the nearest: the loop asks at
    /// poses a cycle apart.
    pub fn distance_below_remembering(
        &self,
        head: &HeadModel,
        head_from_coil: &Isometry3<f64>,
        cutoff: f64,
        memory: &mut ClearanceMemory,
    ) -> f64 {
        self.distance_below_in(head, head_from_coil, cutoff, Some(memory))
    }

    fn distance_below_in(
        &self,
        head: &HeadModel,
        head_from_coil: &Isometry3<f64>,
        cutoff: f64,
        memory: Option<&mut ClearanceMemory>,
    ) -> f64 {
        // Not a solid (the configuration refuses such a coil): as if cutting in, so every rule
        // keeps it away.
        self.solid().map_or(f64::NEG_INFINITY, |solid| {
            head.shape
                .loop_clearance_below(head_from_coil, &solid, cutoff, memory)
        })
    }
}

/// The head and coil models the unit tests of the goal check and the safety filter share.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::{CoilModel, HeadModel};

    /// An adult head: semi-axes 75, 95 and 110 mm, centred on the head frame.
    pub(crate) fn head() -> HeadModel {
        HeadModel::adult()
    }

    /// A figure-8 coil's envelope: 40 mm radius, 30 mm thick.
    pub(crate) fn coil() -> CoilModel {
        CoilModel::cylinder(0.04, 0.03)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `distance_below` is the exact distance below its cutoff and never claims a point is
    /// nearer than it is (points and coil poses all around the head, cutoffs from inside to far).
    #[test]
    fn distance_below_is_exact_below_the_cutoff_and_a_bound_above() {
        let head = HeadModel::ellipsoid(
            Isometry3::new(
                Vector3::new(0.01, -0.02, 0.005),
                Vector3::new(0.1, 0.2, -0.3),
            ),
            Vector3::new(0.075, 0.095, 0.11),
        )
        .unwrap();
        let coil = CoilModel::cylinder(0.04, 0.03);
        let mut x = 7u64;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..2000 {
            let p = Point3::new(0.4 * next(), 0.4 * next(), 0.4 * next());
            let exact = head.distance(&p);
            for cutoff in [-0.01, 0.0, 0.003, 0.03, 0.1] {
                let d = head.distance_below(&p, cutoff);
                if exact < cutoff {
                    assert_eq!(d, exact);
                } else {
                    assert!(d >= cutoff && d <= exact + 1e-12, "{d} {exact} {cutoff}");
                }
            }
            let pose = Isometry3::new(
                p.coords,
                Vector3::new(3.0 * next(), 3.0 * next(), 3.0 * next()),
            );
            let exact = coil.distance(&head, &pose);
            for cutoff in [-0.002, 0.0, 0.01] {
                let d = coil.distance_below(&head, &pose, cutoff);
                if exact < cutoff {
                    assert_eq!(d, exact);
                } else {
                    assert!(d >= cutoff, "{d} {exact} {cutoff}");
                }
            }
        }
    }

    #[test]
    fn ellipsoid_distance_is_exact_on_the_axes_and_bounded_elsewhere() {
        let r = Vector3::new(0.08, 0.10, 0.12);
        assert!((ellipsoid_distance(&Vector3::new(0.0, 0.0, 0.125), &r) - 0.005).abs() < 1e-12);
        assert!((ellipsoid_distance(&Vector3::new(0.2, 0.0, 0.0), &r) - 0.12).abs() < 1e-12);
        assert!(ellipsoid_distance(&Vector3::zeros(), &r) < 0.0);
        // Against brute force over the surface.
        let p = Vector3::new(0.1, 0.07, 0.09);
        let mut best = f64::INFINITY;
        for i in 0..400 {
            for j in 0..400 {
                let th = std::f64::consts::PI * f64::from(i) / 399.0;
                let ph = std::f64::consts::TAU * f64::from(j) / 400.0;
                let y = Vector3::new(
                    r.x * th.sin() * ph.cos(),
                    r.y * th.sin() * ph.sin(),
                    r.z * th.cos(),
                );
                best = best.min((p - y).norm());
            }
        }
        let d = ellipsoid_distance(&p, &r);
        assert!(d <= best + 1e-9 && best - d < 2e-4, "{d} vs {best}");
    }
}
