//! The queries every consumer of the head asks, whatever its shape: signed distance, the
//! nearest surface point with its normal, a ray's hit, the coil's clearance, a bounding box.
//! All in the head (marker) frame, metres.

use crate::error::HeadError;
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};

/// A point on the surface nearest a query point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfacePoint {
    /// The surface point.
    pub point: Point3<f64>,
    /// The outward normal there (for a query point off the surface: the direction from the
    /// surface point to it, turned outward, which is the distance field's gradient).
    pub normal: Unit<Vector3<f64>>,
    /// The query point's signed distance: positive outside, negative inside, m.
    pub signed_distance: f64,
}

/// Where a ray first meets the surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Distance along the (unit) ray, m.
    pub distance: f64,
    /// The point.
    pub point: Point3<f64>,
    /// The outward normal there.
    pub normal: Unit<Vector3<f64>>,
}

/// An axis-aligned box, head frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Point3<f64>,
    /// Upper corner.
    pub max: Point3<f64>,
}

impl Aabb {
    /// The box around `points` (`None` when there are none).
    pub fn around<'a>(points: impl IntoIterator<Item = &'a Point3<f64>>) -> Option<Self> {
        let mut it = points.into_iter();
        let first = *it.next()?;
        Some(it.fold(
            Self {
                min: first,
                max: first,
            },
            |b, p| Self {
                min: b.min.inf(p),
                max: b.max.sup(p),
            },
        ))
    }

    /// The largest side, m.
    pub fn extent(&self) -> f64 {
        (self.max - self.min).max()
    }

    /// Distance from `p` to the box (0 inside): a lower bound of the distance to anything in it.
    pub fn distance(&self, p: &Point3<f64>) -> f64 {
        let below = self.min - p;
        let above = p - self.max;
        below.sup(&above).sup(&Vector3::zeros()).norm()
    }
}

/// The coil's rim every 45° and its centre, as (cos, sin) offsets of its radius: the points a
/// coil is sampled at, on its face and on its back.
pub const COIL_RIM: [(f64, f64); 9] = {
    const H: f64 = std::f64::consts::FRAC_1_SQRT_2;
    [
        (1.0, 0.0),
        (H, H),
        (0.0, 1.0),
        (-H, H),
        (-1.0, 0.0),
        (-H, -H),
        (0.0, -1.0),
        (H, -H),
        (0.0, 0.0),
    ]
};

/// The coil as the solid it is: a cylinder (a disc with thickness) in the coil frame, its face
/// at the origin, +z (its approach axis) into the head, its body behind the face (z from
/// `-thickness` to 0), `radius` as seen from the head.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CoilSolid {
    radius: f64,
    thickness: f64,
}

impl CoilSolid {
    /// A coil of `radius` and `thickness`, metres.
    pub fn new(radius: f64, thickness: f64) -> Result<Self, HeadError> {
        if radius.is_finite() && thickness.is_finite() && radius > 0.0 && thickness > 0.0 {
            Ok(Self { radius, thickness })
        } else {
            Err(HeadError::BadCoil { radius, thickness })
        }
    }

    /// Its radius, m.
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Its thickness, m.
    pub fn thickness(&self) -> f64 {
        self.thickness
    }

    /// The cylinder as parry holds it (its axis along its own y), centred.
    pub(crate) fn cylinder(&self) -> parry3d_f64::shape::Cylinder {
        parry3d_f64::shape::Cylinder::new(self.thickness / 2.0, self.radius)
    }

    /// The face's and back's centres and their rims every 45°, head frame: where a coil facing
    /// the head is nearest it, to seed the exact search and to measure how deep a coil cutting
    /// in goes.
    pub(crate) fn sample_points(&self, head_from_coil: &Isometry3<f64>) -> [Point3<f64>; 18] {
        let r = self.radius;
        std::array::from_fn(|i| {
            let (c, s) = COIL_RIM[i % 9];
            let z = if i < 9 { 0.0 } else { -self.thickness };
            head_from_coil * Point3::new(r * c, r * s, z)
        })
    }

    /// `head_from_cylinder` for the coil at `head_from_coil`: the cylinder's centre half its
    /// thickness behind the face, its y turned onto the coil's z.
    pub(crate) fn head_from_cylinder(&self, head_from_coil: &Isometry3<f64>) -> Isometry3<f64> {
        let coil_from_cylinder = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, -self.thickness / 2.0),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2),
        );
        head_from_coil * coil_from_cylinder
    }
}

/// A head's shape. Implementations answer in the head frame, metres, and allocate nothing per
/// query where the loop asks (near the head; see the crate's limits).
pub trait HeadShape {
    /// Signed distance from `p` to the surface: positive outside, negative inside.
    fn signed_distance(&self, p: &Point3<f64>) -> f64;

    /// The surface point nearest `p`, its outward normal, and `p`'s signed distance.
    fn nearest(&self, p: &Point3<f64>) -> SurfacePoint;

    /// The first point within `max_distance` where the ray from `origin` along `direction`
    /// meets the surface (from outside or from inside).
    fn ray_hit(
        &self,
        origin: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_distance: f64,
    ) -> Option<RayHit>;

    /// A box that holds the whole head.
    fn bounds(&self) -> Aabb;

    /// The point the planner's shell is built around: the ellipsoid's centre, the middle of a
    /// mesh's box.
    fn centre(&self) -> Point3<f64>;

    /// How far the head reaches from [`Self::centre`] along the unit direction `d` (its
    /// farthest surface point on that ray), m.
    fn radius_along(&self, d: &Vector3<f64>) -> f64;

    /// The coil's least distance to the head, as the solid it is: positive when clear, 0 when
    /// touching, negative when it cuts into the head (then as deep as its deepest face or rim
    /// point, a lower bound of the depth).
    fn coil_clearance(&self, head_from_coil: &Isometry3<f64>, coil: &CoilSolid) -> f64;

    /// [`Self::signed_distance`] where it is below `cutoff`; elsewhere a lower bound of it that
    /// is at least `cutoff` (the distance to the bounding box), which spares the exact query for
    /// the many points a check only needs to know are far enough.
    fn distance_below(&self, p: &Point3<f64>, cutoff: f64) -> f64 {
        let bound = self.bounds().distance(p);
        if bound >= cutoff {
            bound
        } else {
            self.signed_distance(p)
        }
    }

    /// [`Self::coil_clearance`] where it is below `cutoff`; elsewhere a lower bound of it that
    /// is at least `cutoff`.
    fn coil_clearance_below(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
    ) -> f64 {
        // The coil lies within a sphere of its half-diagonal about the cylinder's centre.
        let centre = head_from_coil * Point3::new(0.0, 0.0, -coil.thickness / 2.0);
        let reach = coil.radius.hypot(coil.thickness / 2.0);
        let bound = self.bounds().distance(&centre) - reach;
        if bound >= cutoff {
            bound
        } else {
            self.coil_clearance(head_from_coil, coil)
        }
    }
}

/// What a distance query knows at a point: the exact signed distance, or only a lower bound
/// of it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Known {
    /// The exact signed distance.
    Exact(f64),
    /// A lower bound of the signed distance.
    Below(f64),
}
