//! A grid of targets around one, on the head model's surface.
//!
//! Motor mapping stimulates a grid of points around the hotspot. From a target (`head_from_coil`,
//! its +z the approach axis into the head) the grid is centred where the target's axis meets the
//! head model's surface: `rows × cols` points, its rows along the target's x axis. The points are
//! walked on the surface (in 0.5 mm steps, each taken back onto the surface at its nearest point,
//! the direction kept tangent): first along the target's y to the row, then along its x to the column, so that
//! neighbours in a row are `spacing_m` apart on the surface. Each coil is aimed along the
//! surface normal there (+z into the head), its x axis the walking direction, and backed off the
//! surface by the target's own standoff (its distance along its axis to the surface). The centre
//! point is the target re-aimed along the normal.

use mocomp_control::HeadModel;
use mocomp_geom::nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Unit, UnitQuaternion, Vector3};
use mocomp_head::{Head, HeadShape};

/// The grid's shape.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GridParams {
    /// Distance between neighbouring points, m. [0.01]
    pub spacing_m: f64,
    /// Points along the target's y axis. [3]
    pub rows: usize,
    /// Points along the target's x axis. [3]
    pub cols: usize,
}

impl Default for GridParams {
    fn default() -> Self {
        Self {
            spacing_m: 0.01,
            rows: 3,
            cols: 3,
        }
    }
}

/// The most points along either side of a grid.
pub const MAX_SIDE: usize = 15;

/// Why no grid.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GridError {
    /// A parameter out of range, by its key.
    #[error("{key} = {value}: {problem}")]
    Param {
        /// The key.
        key: &'static str,
        /// The value given.
        value: f64,
        /// What is wrong.
        problem: &'static str,
    },
    /// The target's approach axis does not meet the head model.
    #[error("the target's approach axis (+z) does not meet the head model")]
    AxisMissesHead,
    /// The target is not a finite transform.
    #[error("the target is not a finite transform")]
    NotFinite,
}

/// One point of a grid.
#[derive(Debug, Clone, PartialEq)]
pub struct GridPoint {
    /// Row (along the target's y) and column (along its x), from 0.
    pub row: usize,
    /// See `row`.
    pub col: usize,
    /// The coil there, `head_from_coil`.
    pub head_from_coil: Isometry3<f64>,
}

/// The grid around `target` (`head_from_coil`) on `head`, row by row.
pub fn grid_around(
    head: &HeadModel,
    target: &Isometry3<f64>,
    p: &GridParams,
) -> Result<Vec<GridPoint>, GridError> {
    if !(p.spacing_m.is_finite() && p.spacing_m > 0.0) {
        return Err(GridError::Param {
            key: "spacing_m",
            value: p.spacing_m,
            problem: "must be finite and > 0",
        });
    }
    for (key, n) in [("rows", p.rows), ("cols", p.cols)] {
        if n == 0 || n > MAX_SIDE {
            return Err(GridError::Param {
                key,
                value: n as f64,
                problem: "must be 1 to 15",
            });
        }
    }
    let finite = target.translation.vector.iter().all(|x| x.is_finite())
        && target.rotation.coords.iter().all(|x| x.is_finite());
    if !finite {
        return Err(GridError::NotFinite);
    }
    let shape = head.shape();
    let origin = Point3::from(target.translation.vector);
    let axis = Unit::new_normalize(target.rotation * Vector3::z());
    // From outside only: a target inside the head has no standoff to keep.
    if shape.signed_distance(&origin) < 0.0 {
        return Err(GridError::AxisMissesHead);
    }
    let hit = shape
        .ray_hit(&origin, &axis, MAX_REACH_M)
        .ok_or(GridError::AxisMissesHead)?;
    let standoff = hit.distance;
    let n = hit.normal.into_inner();
    let x_target = target.rotation * Vector3::x();
    let tx = tangent(&x_target, &n).ok_or(GridError::AxisMissesHead)?;
    let ty = n.cross(&tx);
    let mut out = Vec::with_capacity(p.rows * p.cols);
    for row in 0..p.rows {
        let v = (row as f64 - (p.rows - 1) as f64 / 2.0) * p.spacing_m;
        let (row_start, y_dir, row_normal) = walk(shape, &hit.point, &ty, v)?;
        // The row runs along the target's x carried to the row's start.
        let x_row = y_dir.cross(&row_normal);
        for col in 0..p.cols {
            let u = (col as f64 - (p.cols - 1) as f64 / 2.0) * p.spacing_m;
            let (q, x_dir, nq) = walk(shape, &row_start, &x_row, u)?;
            let x = tangent(&x_dir, &nq).ok_or(GridError::AxisMissesHead)?;
            let z = -nq;
            let y = z.cross(&x);
            let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
            out.push(GridPoint {
                row,
                col,
                head_from_coil: Isometry3::from_parts(
                    (q + nq * standoff).into(),
                    UnitQuaternion::from_rotation_matrix(&rot),
                ),
            });
        }
    }
    Ok(out)
}

/// How far along its axis a target may be from the head, m.
const MAX_REACH_M: f64 = 1.0;

/// Where a walk on the surface ends: the point, the walking direction and the outward normal.
type WalkEnd = (Point3<f64>, Vector3<f64>, Vector3<f64>);

/// Walks `dist` (m, negative: backwards) on the head's surface from `start` in direction `dir`
/// (tangent), in steps of at most 0.5 mm, each taken back onto the surface at its nearest point,
/// the direction kept tangent; returns the end, the direction and the outward normal there.
fn walk(
    shape: &Head,
    start: &Point3<f64>,
    dir: &Vector3<f64>,
    dist: f64,
) -> Result<WalkEnd, GridError> {
    let n = (dist.abs() / 5e-4).ceil().max(1.0);
    let step = dist / n;
    let at = shape.nearest(start);
    let (mut p, mut d, mut normal) = (at.point, *dir, at.normal.into_inner());
    for _ in 0..n as usize {
        let next = shape.nearest(&(p + d * step));
        normal = next.normal.into_inner();
        d = tangent(&d, &normal).ok_or(GridError::AxisMissesHead)?;
        p = next.point;
    }
    Ok((p, d, normal))
}

/// `v` projected onto the plane normal to `n`, unit length.
fn tangent(v: &Vector3<f64>, n: &Vector3<f64>) -> Option<Vector3<f64>> {
    let t = v - n * v.dot(n);
    (t.norm() > 1e-9).then(|| t.normalize())
}

/// A coil over the scalp point nearest `near` (head frame): its face `standoff_m` off the
/// surface along the scalp's normal, +z into the head, its x along the head frame's +y (front)
/// carried onto the scalp's tangent plane (or its +x where +y is the normal). The normal is the
/// distance field's gradient 30 mm out, which smooths a mesh's facets over about a coil's size.
pub fn coil_over(
    head: &HeadModel,
    near: &Point3<f64>,
    standoff_m: f64,
) -> Result<Isometry3<f64>, GridError> {
    if !(near.coords.iter().all(|x| x.is_finite()) && standoff_m.is_finite()) {
        return Err(GridError::NotFinite);
    }
    let shape = head.shape();
    let first = shape.nearest(near);
    let out = shape.nearest(&(first.point + first.normal.into_inner() * NORMAL_REACH_M));
    let n = out.normal.into_inner();
    let x = tangent(&Vector3::y(), &n)
        .or_else(|| tangent(&Vector3::x(), &n))
        .ok_or(GridError::AxisMissesHead)?;
    let z = -n;
    let y = z.cross(&x);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    Ok(Isometry3::from_parts(
        (out.point + n * standoff_m).into(),
        UnitQuaternion::from_rotation_matrix(&rot),
    ))
}

/// How far out [`coil_over`] reads the scalp's normal, m.
const NORMAL_REACH_M: f64 = 0.03;

/// The point a coil's approach axis meets the head at, in the head's frame (for reports and
/// tests).
pub fn surface_point(head: &HeadModel, head_from_coil: &Isometry3<f64>) -> Option<Point3<f64>> {
    let shape = head.shape();
    let o = Point3::from(head_from_coil.translation.vector);
    if shape.signed_distance(&o) < 0.0 {
        return None;
    }
    let axis = Unit::new_normalize(head_from_coil.rotation * Vector3::z());
    shape.ray_hit(&o, &axis, MAX_REACH_M).map(|h| h.point)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use proptest::prelude::*;

    fn placed() -> Isometry3<f64> {
        Isometry3::new(Vector3::new(0.0, 0.01, 0.02), Vector3::new(0.0, 0.0, 0.1))
    }

    fn head() -> HeadModel {
        HeadModel::ellipsoid(placed(), Vector3::new(0.075, 0.095, 0.11)).unwrap()
    }

    /// Where the axis of `pose` meets the head, and the outward normal there.
    fn axis_hit(h: &HeadModel, pose: &Isometry3<f64>) -> (f64, Vector3<f64>) {
        let axis = Unit::new_normalize(pose.rotation * Vector3::z());
        let hit = h
            .shape()
            .ray_hit(&Point3::from(pose.translation.vector), &axis, 1.0)
            .unwrap();
        (hit.distance, hit.normal.into_inner())
    }

    /// On top of the head, 3 mm off, tilted forward by `tilt` (rad) about the head's x.
    fn target(tilt: f64) -> Isometry3<f64> {
        let up = Isometry3::rotation(Vector3::x() * tilt)
            * Isometry3::from_parts(
                mocomp_geom::nalgebra::Translation3::new(0.0, 0.0, 0.113),
                UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
            );
        placed() * up
    }

    fn check(grid: &[GridPoint], h: &HeadModel, standoff: f64, spacing: f64, cols: usize) {
        for g in grid {
            // Aimed along the normal: the axis meets the surface at the standoff, square.
            let (t, n) = axis_hit(h, &g.head_from_coil);
            assert!((t - standoff).abs() < 1e-9, "standoff {t} vs {standoff}");
            let z = g.head_from_coil.rotation * Vector3::z();
            assert!((z + n).norm() < 1e-9, "not along the normal");
        }
        // Neighbours in a row `spacing` apart on the surface (their chord is shorter by the
        // curvature: under 0.1 % at 12 mm on a 7.5 cm radius).
        for w in grid.windows(2).filter(|w| w[0].row == w[1].row) {
            let a = surface_point(h, &w[0].head_from_coil).unwrap();
            let b = surface_point(h, &w[1].head_from_coil).unwrap();
            let d = (a - b).norm();
            assert!((d - spacing).abs() < 0.01 * spacing, "{d} vs {spacing}");
        }
        assert_eq!(grid.len() % cols, 0);
    }

    #[test]
    fn a_three_by_three_grid_is_on_the_surface_spaced_and_aimed_along_the_normals() {
        let h = head();
        let t = target(0.2);
        let grid = grid_around(&h, &t, &GridParams::default()).unwrap();
        assert_eq!(grid.len(), 9);
        let standoff = axis_hit(&h, &t).0;
        check(&grid, &h, standoff, 0.01, 3);
        // The centre point meets the surface where the target's axis does.
        let c = surface_point(&h, &grid[4].head_from_coil).unwrap();
        let s = surface_point(&h, &t).unwrap();
        assert!((c - s).norm() < 1e-9);
        // Columns run along the target's x: the first column is on its -x side.
        let first = surface_point(&h, &grid[3].head_from_coil).unwrap();
        let x = t.rotation * Vector3::x();
        assert!((first - s).dot(&x) < -0.009);
    }

    #[test]
    fn a_coil_over_a_point_faces_the_scalp_at_its_standoff() {
        let h = head();
        for near in [
            Point3::new(0.0, 0.01, 0.2),
            Point3::new(0.09, 0.01, 0.02),
            Point3::new(0.02, -0.12, 0.05),
        ] {
            let pose = coil_over(&h, &near, 0.003).unwrap();
            let (t, n) = axis_hit(&h, &pose);
            assert!((t - 0.003).abs() < 1e-6, "{near}: {t}");
            let z = pose.rotation * Vector3::z();
            assert!((z + n).norm() < 1e-6, "{near}: not along the normal");
            // The face's centre is 3 mm off the head.
            let d = h.distance(&Point3::from(pose.translation.vector));
            assert!((d - 0.003).abs() < 1e-6, "{near}: {d}");
        }
        assert_eq!(
            coil_over(&h, &Point3::new(f64::NAN, 0.0, 0.0), 0.003).unwrap_err(),
            GridError::NotFinite
        );
    }

    #[test]
    fn bad_parameters_and_a_target_that_misses_the_head_are_refused_by_name() {
        let h = head();
        let bad = |p: GridParams| grid_around(&h, &target(0.0), &p).unwrap_err();
        assert!(matches!(
            bad(GridParams {
                spacing_m: 0.0,
                ..GridParams::default()
            }),
            GridError::Param {
                key: "spacing_m",
                ..
            }
        ));
        assert!(matches!(
            bad(GridParams {
                rows: 0,
                ..GridParams::default()
            }),
            GridError::Param { key: "rows", .. }
        ));
        assert!(matches!(
            bad(GridParams {
                cols: 16,
                ..GridParams::default()
            }),
            GridError::Param { key: "cols", .. }
        ));
        // Pointing away from the head.
        let away = target(0.0) * Isometry3::rotation(Vector3::x() * std::f64::consts::PI);
        assert_eq!(
            grid_around(&h, &away, &GridParams::default()).unwrap_err(),
            GridError::AxisMissesHead
        );
    }

    proptest! {
        #![proptest_config(mocomp_testkit::proptest_config(64, 20))]
        #[test]
        fn any_grid_on_the_head_keeps_the_standoff_the_normals_and_the_spacing(
            tilt in -0.8f64..0.8,
            spacing in 0.004f64..0.012,
            rows in 1usize..6,
            cols in 1usize..6,
        ) {
            let h = head();
            let t = target(tilt);
            let p = GridParams { spacing_m: spacing, rows, cols };
            let grid = grid_around(&h, &t, &p).unwrap();
            prop_assert_eq!(grid.len(), rows * cols);
            let standoff = axis_hit(&h, &t).0;
            check(&grid, &h, standoff, spacing, cols);
        }
    }
}
