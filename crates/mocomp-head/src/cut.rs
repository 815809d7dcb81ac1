//! Where a scan ends inside the head. A scalp segmented from a volume that does not hold the
//! whole head is closed by the volume's face: the model is flat there, and the real head (an ear,
//! the brow, the neck) goes on beyond it. The head model keeps each such patch of the volume's
//! face, so that a goal near one is refused rather than trusted to a surface that is not the
//! patient's.

use crate::shape::CoilSolid;
use mocomp_geom::nalgebra::{Isometry3, Point3, Rotation3, Unit, UnitQuaternion, Vector3};

/// The patch of one of the scan's faces the head reaches: a rectangle in the face's plane that
/// holds every head voxel on that face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanCut {
    /// Which way the face looks in the image's frame (`left`, `right`, `posterior`, `anterior`,
    /// `inferior` or `superior`).
    pub side: &'static str,
    /// The rectangle's centre, m.
    pub centre: Point3<f64>,
    /// The plane's normal, out of the scan.
    pub outward: Unit<Vector3<f64>>,
    /// The rectangle's first axis, in the plane (the second is `outward × along`).
    pub along: Unit<Vector3<f64>>,
    /// Half its sides along `along` and along the second axis, m.
    pub half_m: [f64; 2],
}

impl ScanCut {
    /// The same patch in frame `b`, for a patch given in frame `a`.
    pub fn transformed(&self, b_from_a: &Isometry3<f64>) -> Self {
        Self {
            centre: b_from_a * self.centre,
            outward: b_from_a.rotation * self.outward,
            along: b_from_a.rotation * self.along,
            ..*self
        }
    }

    /// The least distance from the coil (the solid it is) at `head_from_coil` to the patch, m
    /// (0 when they touch or cross).
    pub fn coil_distance(&self, head_from_coil: &Isometry3<f64>, coil: &CoilSolid) -> f64 {
        let across = self.outward.cross(&self.along);
        let frame = Rotation3::from_basis_unchecked(&[
            self.along.into_inner(),
            across,
            self.outward.into_inner(),
        ]);
        let head_from_patch = Isometry3::from_parts(
            self.centre.coords.into(),
            UnitQuaternion::from_rotation_matrix(&frame),
        );
        // A plate a micrometre thick: parry's box against its cylinder.
        let plate =
            parry3d_f64::shape::Cuboid::new(Vector3::new(self.half_m[0], self.half_m[1], 1e-6));
        let convex = coil.convex();
        parry3d_f64::query::distance(
            &convex.placed(head_from_coil),
            convex.shape(),
            &head_from_patch,
            &plate,
        )
        // A pair parry's dispatcher handles; were it not, touching.
        .unwrap_or(0.0)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    /// The left face of a scan, x = -90 mm, the head on it within y, z ∈ [-20, 20] mm.
    fn left() -> ScanCut {
        ScanCut {
            side: "left",
            centre: Point3::new(-0.09, 0.0, 0.0),
            outward: -Vector3::x_axis(),
            along: Vector3::y_axis(),
            half_m: [0.02, 0.02],
        }
    }

    /// A coil whose face centre is at `face`, its axis (+z) along `axis`.
    fn coil_at(face: Point3<f64>, axis: Vector3<f64>) -> Isometry3<f64> {
        // Turned half round x when the axis is -z (no shortest rotation then).
        let rot = UnitQuaternion::rotation_between(&Vector3::z(), &axis).unwrap_or_else(|| {
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
        });
        Isometry3::from_parts(face.coords.into(), rot)
    }

    #[test]
    fn a_coil_s_distance_to_the_patch_is_the_geometry_s() {
        let cut = left();
        let coil = CoilSolid::new(0.04, 0.03).unwrap();
        // Facing the patch from outside, 5 mm off: its face is 5 mm from the plate.
        let facing = coil_at(Point3::new(-0.095, 0.0, 0.0), Vector3::x());
        assert!((cut.coil_distance(&facing, &coil) - 0.005).abs() < 1e-6);
        // Above the patch (z from 60 mm), facing down onto the crown: its rim's lowest point is
        // 40 mm above the plate's top edge, 20 mm.
        let above = coil_at(Point3::new(-0.09, 0.0, 0.1), -Vector3::z());
        let d = cut.coil_distance(&above, &coil);
        assert!((d - 0.08).abs() < 1e-6, "{d}");
        // Beside the patch in the plane, across its side: its rim 10 mm from the edge.
        let beside = coil_at(Point3::new(-0.09, 0.07, 0.0), -Vector3::x());
        let d = cut.coil_distance(&beside, &coil);
        assert!((d - 0.01).abs() < 1e-6, "{d}");
        // Its body across the plate (face inside the scan, back beyond it): touching.
        let through = coil_at(Point3::new(-0.08, 0.0, 0.0), Vector3::x());
        assert_eq!(cut.coil_distance(&through, &coil), 0.0);
        // Carried into another frame with the coil, the same distance.
        let b_from_a = Isometry3::new(Vector3::new(0.1, -0.2, 0.3), Vector3::new(0.4, 0.5, -0.6));
        let d_b = cut
            .transformed(&b_from_a)
            .coil_distance(&(b_from_a * beside), &coil);
        assert!((d_b - 0.01).abs() < 1e-6, "{d_b}");
    }
}
