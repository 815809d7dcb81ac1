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
}
