//! The patient's head as a shape: what every safety decision is made against.
//!
//! [`HeadShape`] is the one set of questions (signed distance, nearest surface point and normal,
//! a ray's hit, the coil's clearance as the solid it is, a bounding box, the reach from its
//! centre); [`Ellipsoid`] and [`MeshHead`] (the scalp from a scan, behind a distance field and a
//! bounding-volume hierarchy) answer them, and [`Head`] is either, cheap to clone. [`sampled`]
//! is the coil's clearance as the control loop asks it. [`formats`] decodes the surfaces clinics have (STL, OBJ,
//! PLY, GIfTI, FreeSurfer) from bytes; [`repair`] makes what was read into one closed, outward
//! surface and says what it changed; [`inspect`] does both and reports.
//!
//! **Limits.** This crate does no I/O and keeps no clock: the caller reads the file and hands
//! over its bytes. Coordinates are metres in whatever frame the caller gives (the head marker's
//! frame once registered); a file's millimetres are converted once, on reading. A query in the
//! distance field's grid allocates nothing (beyond it, parry's traversal keeps a small stack that
//! may spill to the heap). Volumes (NIfTI) are not read here yet.

pub mod casing;
mod clearance;
mod climb;
pub mod cut;
pub mod ellipsoid;
pub mod error;
pub mod field;
pub mod formats;
pub mod inspect;
pub mod mesh;
pub mod radial;
pub mod reframed;
pub mod render;
pub mod repair;
pub mod sampled;
pub mod shape;

pub use cut::ScanCut;
pub use ellipsoid::{Ellipsoid, ellipsoid_distance};
pub use error::HeadError;
pub use mesh::{Mesh, MeshHead};
pub use reframed::Reframed;
pub use repair::{Repairs, repair};
pub use shape::{Aabb, CoilSolid, HeadShape, RayHit, SurfacePoint};

use mocomp_geom::nalgebra::{Isometry3, Point3, Unit, Vector3};
use std::sync::Arc;

/// A head: an ellipsoid or a mesh. Clones share the mesh.
#[derive(Debug, Clone)]
pub enum Head {
    /// The ellipsoid model.
    Ellipsoid(Ellipsoid),
    /// The patient's scalp.
    Mesh(Arc<MeshHead>),
}

impl Head {
    fn shape(&self) -> &dyn HeadShape {
        match self {
            Self::Ellipsoid(e) => e,
            Self::Mesh(m) => m.as_ref(),
        }
    }

    /// The coil's clearance as the control loop takes it, several times a cycle: never more
    /// room than there is ([`Ellipsoid::loop_clearance_below`],
    /// [`MeshHead::loop_clearance_below`]); `memory`, the call site's from its last call, spares
    /// a scalp's samples that cannot be the nearest. Where it is at least `cutoff`, any value of
    /// at least `cutoff`.
    pub fn loop_clearance_below(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
        memory: Option<&mut sampled::ClearanceMemory>,
    ) -> f64 {
        match self {
            Self::Ellipsoid(e) => e.loop_clearance_below(head_from_coil, coil, cutoff),
            Self::Mesh(m) => m.loop_clearance_below(head_from_coil, coil, cutoff, memory),
        }
    }

    /// The coil's clearance as the simulated world feels it: the loop's samples without the
    /// margin the loop keeps for what may lie between them (the head as it is). Where it is at
    /// least `cutoff`, any value of at least `cutoff`.
    pub fn sampled_clearance_below(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
    ) -> f64 {
        match self {
            Self::Ellipsoid(e) => e.loop_clearance_below(head_from_coil, coil, cutoff),
            Self::Mesh(m) => m.coil_clearance_sampled(head_from_coil, coil, cutoff),
        }
    }

    /// The coil's clearance a report measures: on a scalp the exact one (GJK on the triangles
    /// that can be nearest: tens of microseconds at 100 k triangles, not for the loop); on the
    /// ellipsoid the loop's, as reports always measured it.
    pub fn reported_clearance(&self, head_from_coil: &Isometry3<f64>, coil: &CoilSolid) -> f64 {
        match self {
            Self::Ellipsoid(e) => e.loop_clearance_below(head_from_coil, coil, f64::INFINITY),
            Self::Mesh(m) => m.coil_clearance(head_from_coil, coil),
        }
    }

    /// Where the scan the scalp came from ends inside the head (none for an ellipsoid or a
    /// surface read whole): the model is flat there, not the patient.
    pub fn cuts(&self) -> &[ScanCut] {
        match self {
            Self::Ellipsoid(_) => &[],
            Self::Mesh(m) => m.cuts(),
        }
    }

    /// The ellipsoid, when the head is one (for what only an ellipsoid has: its axes).
    pub fn as_ellipsoid(&self) -> Option<&Ellipsoid> {
        match self {
            Self::Ellipsoid(e) => Some(e),
            Self::Mesh(_) => None,
        }
    }

    /// The scalp, when the head is one (for what only a surface has: its vertices and
    /// triangles).
    pub fn scalp(&self) -> Option<&MeshHead> {
        match self {
            Self::Ellipsoid(_) => None,
            Self::Mesh(m) => Some(m),
        }
    }
}

/// Two ellipsoids are equal by their axes; two scalps only when they are the same one.
impl PartialEq for Head {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (Self::Ellipsoid(a), Self::Ellipsoid(b)) => a == b,
            (Self::Mesh(a), Self::Mesh(b)) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

impl HeadShape for Head {
    fn signed_distance(&self, p: &Point3<f64>) -> f64 {
        self.shape().signed_distance(p)
    }
    fn nearest(&self, p: &Point3<f64>) -> SurfacePoint {
        self.shape().nearest(p)
    }
    fn ray_hit(
        &self,
        origin: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_distance: f64,
    ) -> Option<RayHit> {
        self.shape().ray_hit(origin, direction, max_distance)
    }
    fn bounds(&self) -> Aabb {
        self.shape().bounds()
    }
    fn centre(&self) -> Point3<f64> {
        self.shape().centre()
    }
    fn radius_along(&self, d: &Vector3<f64>) -> f64 {
        self.shape().radius_along(d)
    }
    fn coil_clearance(&self, head_from_coil: &Isometry3<f64>, coil: &CoilSolid) -> f64 {
        self.shape().coil_clearance(head_from_coil, coil)
    }
    // Each shape's own spares, not the default's box bound; matched, not through the vtable:
    // the loop asks these many times a cycle.
    fn distance_below(&self, p: &Point3<f64>, cutoff: f64) -> f64 {
        match self {
            Self::Ellipsoid(e) => e.distance_below(p, cutoff),
            Self::Mesh(m) => m.distance_below(p, cutoff),
        }
    }
    fn coil_clearance_below(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
    ) -> f64 {
        match self {
            Self::Ellipsoid(e) => e.coil_clearance_below(head_from_coil, coil, cutoff),
            Self::Mesh(m) => m.coil_clearance_below(head_from_coil, coil, cutoff),
        }
    }
}
