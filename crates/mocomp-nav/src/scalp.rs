//! The head model a registration fits to, in the image's frame, and where that model is not the
//! patient's skin: a scan that ends inside the head is closed by the volume's flat face
//! ([`ScanCut`]), and the real ear, brow or neck goes on beyond it. A swept point whose nearest
//! model point lies on such a face (or within [`CUT_MARGIN_M`] of it) would be pulled onto a
//! plane the patient does not have, so it never enters a fit.

use mocomp_geom::nalgebra::Point3;
use mocomp_head::{HeadShape, ScanCut, SurfacePoint};

/// How close to a scan's cut a model point still counts as the cut, m: the segmented surface
/// bends onto the face over a few voxels.
pub const CUT_MARGIN_M: f64 = 5e-3;

/// The scalp in the image's frame and the scan's cuts in the same frame.
#[derive(Clone, Copy)]
pub struct Scalp<'a> {
    /// The head model, image frame.
    pub shape: &'a dyn HeadShape,
    /// Where the scan cut the head, image frame.
    pub cuts: &'a [ScanCut],
}

impl std::fmt::Debug for Scalp<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scalp")
            .field("cuts", &self.cuts.len())
            .finish_non_exhaustive()
    }
}

impl<'a> Scalp<'a> {
    /// A scalp with no cuts.
    pub fn whole(shape: &'a dyn HeadShape) -> Self {
        Self { shape, cuts: &[] }
    }

    /// The model's surface point nearest `p`, with its outward normal.
    pub fn nearest(&self, p: &Point3<f64>) -> SurfacePoint {
        self.shape.nearest(p)
    }

    /// Whether the model's surface at `surface` (a point on it) is a scan's cut rather than skin.
    pub fn on_cut(&self, surface: &Point3<f64>) -> bool {
        self.cuts.iter().any(|c| {
            let d = surface - c.centre;
            let across = c.outward.cross(&c.along);
            d.dot(&c.outward).abs() <= CUT_MARGIN_M
                && d.dot(&c.along).abs() <= c.half_m[0] + CUT_MARGIN_M
                && d.dot(&across).abs() <= c.half_m[1] + CUT_MARGIN_M
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_geom::nalgebra::{Isometry3, Vector3};
    use mocomp_head::Ellipsoid;

    #[test]
    fn a_point_on_a_cut_s_patch_or_its_margin_is_not_skin() {
        let head = Ellipsoid::new(Isometry3::identity(), Vector3::new(0.08, 0.1, 0.11))
            .expect("an ellipsoid");
        let cut = ScanCut {
            side: "anterior",
            centre: Point3::new(0.0, 0.09, -0.02),
            outward: Vector3::y_axis(),
            along: Vector3::x_axis(),
            half_m: [0.03, 0.02],
        };
        let cuts = [cut];
        let scalp = Scalp {
            shape: &head,
            cuts: &cuts,
        };
        assert!(scalp.on_cut(&Point3::new(0.01, 0.09, -0.02)));
        assert!(scalp.on_cut(&Point3::new(0.034, 0.087, -0.02)));
        assert!(!scalp.on_cut(&Point3::new(0.0, 0.075, -0.02)));
        assert!(!scalp.on_cut(&Point3::new(0.04, 0.09, -0.02)));
        assert!(!Scalp::whole(&head).on_cut(&Point3::new(0.01, 0.09, -0.02)));
    }
}
