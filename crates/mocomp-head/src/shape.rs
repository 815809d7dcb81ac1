//! The queries every consumer of the head asks, whatever its shape: signed distance, the
//! nearest surface point with its normal, a ray's hit, the coil's clearance, a bounding box.
//! All in the head (marker) frame, metres.

use crate::casing::Casing;
use crate::error::HeadError;
use mocomp_geom::nalgebra::{Isometry3, Point3, Translation3, Unit, UnitQuaternion, Vector3};
use std::sync::Arc;

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

/// The coil as the solid it is, in the coil frame (+z, its approach axis, into the head): a
/// cylinder (a disc with thickness: its face at the origin, its body behind it, z from
/// `-thickness` to 0, `radius` as seen from the head), or a casing as drawn
/// ([`crate::casing::Casing`]: its convex hull). Clones share a casing.
#[derive(Debug, Clone, PartialEq)]
pub struct CoilSolid {
    form: Form,
}

#[derive(Debug, Clone, PartialEq)]
enum Form {
    Cylinder { radius: f64, thickness: f64 },
    Casing(Arc<Casing>),
}

/// Which solid a coil is, cheap to keep and compare: the same key, the same solid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SolidKey {
    /// A cylinder of this radius and thickness.
    Cylinder(f64, f64),
    /// The casing of this number ([`Casing::id`]).
    Casing(u64),
}

/// The convex solid parry measures a coil as, and where it sits in the coil frame.
pub(crate) enum Convex<'a> {
    Cylinder(parry3d_f64::shape::Cylinder, Isometry3<f64>),
    /// The hull for parry's shape queries, and its support map for GJK.
    Hull(
        &'a parry3d_f64::shape::ConvexPolyhedron,
        &'a crate::climb::Climb,
    ),
}

impl Convex<'_> {
    /// The shape, for parry's queries.
    pub(crate) fn shape(&self) -> &dyn parry3d_f64::shape::Shape {
        match self {
            Self::Cylinder(c, _) => c,
            Self::Hull(h, _) => *h,
        }
    }

    /// The shape's support map, for GJK against another support map.
    pub(crate) fn support(&self) -> &dyn parry3d_f64::shape::SupportMap {
        match self {
            Self::Cylinder(c, _) => c,
            Self::Hull(_, climb) => *climb,
        }
    }

    /// `head_from_shape` for the coil at `head_from_coil`.
    pub(crate) fn placed(&self, head_from_coil: &Isometry3<f64>) -> Isometry3<f64> {
        match self {
            Self::Cylinder(_, coil_from_cylinder) => head_from_coil * coil_from_cylinder,
            Self::Hull(..) => *head_from_coil,
        }
    }
}

impl CoilSolid {
    /// A coil of `radius` and `thickness`, metres.
    pub fn new(radius: f64, thickness: f64) -> Result<Self, HeadError> {
        if radius.is_finite() && thickness.is_finite() && radius > 0.0 && thickness > 0.0 {
            Ok(Self {
                form: Form::Cylinder { radius, thickness },
            })
        } else {
            Err(HeadError::BadCoil { radius, thickness })
        }
    }

    /// The coil as its casing.
    pub fn casing(casing: Arc<Casing>) -> Self {
        Self {
            form: Form::Casing(casing),
        }
    }

    /// The casing, when the coil is one.
    pub fn as_casing(&self) -> Option<&Casing> {
        match &self.form {
            Form::Casing(c) => Some(c),
            Form::Cylinder { .. } => None,
        }
    }

    /// Which solid it is.
    pub fn key(&self) -> SolidKey {
        match &self.form {
            Form::Cylinder { radius, thickness } => SolidKey::Cylinder(*radius, *thickness),
            Form::Casing(c) => SolidKey::Casing(c.id()),
        }
    }

    /// A sphere holding the solid: its centre (coil frame) and radius, m.
    pub fn bounding_sphere(&self) -> (Point3<f64>, f64) {
        match &self.form {
            Form::Cylinder { radius, thickness } => (
                Point3::new(0.0, 0.0, -thickness / 2.0),
                radius.hypot(thickness / 2.0),
            ),
            Form::Casing(c) => c.bounding_sphere(),
        }
    }

    /// The farthest any point of the solid is from the coil's origin, m.
    pub fn extent(&self) -> f64 {
        match &self.form {
            Form::Cylinder { radius, thickness } => radius.hypot(*thickness),
            Form::Casing(c) => c.extent(),
        }
    }

    /// Its heights along +z, back to face: `(z_min, z_max)`, m.
    pub fn z_span(&self) -> (f64, f64) {
        match &self.form {
            Form::Cylinder { thickness, .. } => (-thickness, 0.0),
            Form::Casing(c) => c.z_span(),
        }
    }

    /// Its box in the coil frame: centre and half extents, m.
    pub(crate) fn local_box(&self) -> (Point3<f64>, Vector3<f64>) {
        match &self.form {
            Form::Cylinder { radius, thickness } => (
                Point3::new(0.0, 0.0, -thickness / 2.0),
                Vector3::new(*radius, *radius, thickness / 2.0),
            ),
            Form::Casing(c) => c.local_box(),
        }
    }

    /// The convex solid parry measures.
    pub(crate) fn convex(&self) -> Convex<'_> {
        match &self.form {
            Form::Cylinder { radius, thickness } => Convex::Cylinder(
                parry3d_f64::shape::Cylinder::new(thickness / 2.0, *radius),
                // Its centre half its thickness behind the face, its y turned onto the coil's z.
                Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, -thickness / 2.0),
                    UnitQuaternion::from_axis_angle(
                        &Vector3::x_axis(),
                        std::f64::consts::FRAC_PI_2,
                    ),
                ),
            ),
            Form::Casing(c) => Convex::Hull(c.hull(), c.climb()),
        }
    }

    /// A lower bound of the distance from `p` (coil frame) to the solid (0 inside): exact for
    /// the cylinder, from the bounding sphere for a casing.
    pub(crate) fn point_distance(&self, p: &Point3<f64>) -> f64 {
        match &self.form {
            Form::Cylinder { radius, thickness } => {
                let radial = (p.x.hypot(p.y) - radius).max(0.0);
                let along = (p.z).max(-thickness - p.z).max(0.0);
                radial.hypot(along)
            }
            Form::Casing(c) => {
                let (centre, reach) = c.bounding_sphere();
                ((p - centre).norm() - reach).max(0.0)
            }
        }
    }

    /// The points a coil facing the head is nearest it at, head frame: to seed the exact
    /// search and to measure how deep a coil cutting in goes. The cylinder's face and back
    /// centres and rims every 45°; a casing's samples.
    pub(crate) fn key_points<'a>(
        &'a self,
        head_from_coil: &'a Isometry3<f64>,
    ) -> impl Iterator<Item = Point3<f64>> + 'a {
        let (cylinder, casing) = match &self.form {
            Form::Cylinder { radius, thickness } => (Some((*radius, *thickness)), None),
            Form::Casing(c) => (None, Some(c.samples())),
        };
        let rims = cylinder.into_iter().flat_map(move |(r, t)| {
            (0..18).map(move |i| {
                let (c, s) = COIL_RIM[i % 9];
                let z = if i < 9 { 0.0 } else { -t };
                head_from_coil * Point3::new(r * c, r * s, z)
            })
        });
        let samples = casing
            .into_iter()
            .flat_map(move |s| s.iter().map(move |p| head_from_coil * p));
        rims.chain(samples)
    }

    /// The cylinder's radius and thickness, when it is one.
    pub(crate) fn as_cylinder(&self) -> Option<(f64, f64)> {
        match &self.form {
            Form::Cylinder { radius, thickness } => Some((*radius, *thickness)),
            Form::Casing(_) => None,
        }
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
    /// the many points a check only needs to know are far enough. Inside, a shape may answer a
    /// cheaper bound of the depth (the ellipsoid does: [`crate::ellipsoid_distance`]).
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
        let (centre, reach) = coil.bounding_sphere();
        let centre = head_from_coil * centre;
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
