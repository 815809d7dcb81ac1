//! A coil's casing as the solid the clearance checks use in place of a cylinder: SimNIBS's
//! `.stl` casings are drawn in the coil's own frame (+z into the head, the origin under the
//! centre of the coil's bottom), so the surface read is the solid where the coil is.
//!
//! The checks measure its **convex hull**, not the surface itself: GJK (the exact queries, the
//! planner's) needs a convex solid, and the hull holds every point of the casing, so a distance
//! to it is never more room than the casing has. A figure-of-eight's hull fills the notch
//! between its wings and the step to its handle: the Magstim D70's is 9 % larger than its
//! casing (381 against 350 cm³), all of it above the face a head meets first. The loop's
//! sampled query ([`crate::sampled`]) takes points spread on the same hull: 3 mm apart along the
//! face's rim (where a tilted coil meets a scalp first), 8 mm on the face (the hull's faces
//! turned towards the head), 12 mm elsewhere, widened together until at most [`MAX_SAMPLES`]
//! remain (the D70: 505).

use crate::climb::Climb;
use crate::error::HeadError;
use mocomp_geom::nalgebra::{Point3, Vector3};
use parry3d_f64::shape::ConvexPolyhedron;
use std::sync::atomic::{AtomicU64, Ordering};

/// The most points a coil is sampled at (the loop's query keeps a value for each).
pub const MAX_SAMPLES: usize = 512;

/// Sample spacing along the face's rim (the hull's edges between a face towards the head and
/// one that is not), m: where a convex coil over a convex scalp is nearest it once tilted.
const RIM_SPACING_M: f64 = 0.003;
/// Sample spacing on the hull's face towards the head, m.
const FACE_SPACING_M: f64 = 0.008;
/// Sample spacing elsewhere on the hull, m.
const OTHER_SPACING_M: f64 = 0.012;
/// A hull face whose outward normal is within this angle of +z faces the head (cosine).
const FACING_COS: f64 = 0.94;

/// Each casing built gets its own number: a memory of one casing's samples says nothing of
/// another's.
static NEXT_ID: AtomicU64 = AtomicU64::new(1);

/// A coil's casing, convex hull and samples, in the coil's frame, metres.
#[derive(Debug, Clone)]
pub struct Casing {
    hull: ConvexPolyhedron,
    /// The hull's support map for GJK, faster than the polyhedron's own scan.
    climb: Climb,
    samples: Vec<Point3<f64>>,
    /// The hull's heights along +z: from its back (`z_min`) to its face (`z_max`).
    z_min: f64,
    z_max: f64,
    /// A sphere that holds the hull: its radius about the box's centre.
    reach: f64,
    /// The hull's farthest point from the coil's origin.
    extent: f64,
    /// Half extents of the hull's box (coil frame) and its centre.
    box_half: Vector3<f64>,
    box_centre: Point3<f64>,
    id: u64,
}

impl PartialEq for Casing {
    fn eq(&self, other: &Self) -> bool {
        self.id == other.id
    }
}

impl Casing {
    /// The casing whose surface has the vertices `vertices` (coil frame, metres; its triangles
    /// do not matter, the hull is of its points), read from `file` (named in errors).
    pub fn new(vertices: &[Point3<f64>], file: &str) -> Result<Self, HeadError> {
        let bad = |why: String| HeadError::BadCasing {
            file: file.to_string(),
            why,
        };
        if let Some(i) = vertices
            .iter()
            .position(|v| !v.coords.iter().all(|c| c.is_finite()))
        {
            return Err(bad(format!("vertex {i} is not finite")));
        }
        if vertices.len() < 4 {
            return Err(bad(format!(
                "{} vertices: a solid needs at least 4",
                vertices.len()
            )));
        }
        let (points, triangles) = parry3d_f64::transformation::convex_hull(vertices);
        let hull = ConvexPolyhedron::from_convex_mesh(points.clone(), &triangles)
            .ok_or_else(|| bad("its points are flat: it encloses no volume".to_string()))?;
        let (mut lo, mut hi) = (points[0], points[0]);
        for p in &points {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let box_centre = mocomp_geom::nalgebra::center(&lo, &hi);
        let reach = points
            .iter()
            .map(|p| (p - box_centre).norm())
            .fold(0.0, f64::max);
        let extent = points.iter().map(|p| p.coords.norm()).fold(0.0, f64::max);
        // parry builds a hull of coplanar points too; a coil is no sheet.
        let thinnest = (hi - lo).min();
        if thinnest.is_nan() || thinnest < 1e-4 {
            return Err(bad(format!(
                "its points are flat ({:.3} mm thick): it encloses no volume",
                thinnest * 1e3
            )));
        }
        let samples = spread(&points, &triangles);
        Ok(Self {
            hull,
            climb: Climb::new(&points, &triangles),
            samples,
            z_min: lo.z,
            z_max: hi.z,
            reach,
            extent,
            box_half: (hi - lo) / 2.0,
            box_centre,
            id: NEXT_ID.fetch_add(1, Ordering::Relaxed),
        })
    }

    /// The convex hull, coil frame.
    pub fn hull(&self) -> &ConvexPolyhedron {
        &self.hull
    }

    /// The hull's support map for GJK (the same points as [`Self::hull`]'s, found by climbing
    /// its edges).
    pub(crate) fn climb(&self) -> &Climb {
        &self.climb
    }

    /// The points the loop's query samples it at, on the hull's surface, coil frame.
    pub fn samples(&self) -> &[Point3<f64>] {
        &self.samples
    }

    /// From the hull's back to its face along +z, m: `(z_min, z_max)`.
    pub fn z_span(&self) -> (f64, f64) {
        (self.z_min, self.z_max)
    }

    /// A sphere holding the hull: centre (coil frame) and radius, m.
    pub fn bounding_sphere(&self) -> (Point3<f64>, f64) {
        (self.box_centre, self.reach)
    }

    /// The hull's box in the coil frame: centre and half extents, m.
    pub fn local_box(&self) -> (Point3<f64>, Vector3<f64>) {
        (self.box_centre, self.box_half)
    }

    /// The farthest any point of the hull is from the coil's origin, m.
    pub fn extent(&self) -> f64 {
        self.extent
    }

    /// This casing's own number (for memories of its samples).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// Its outline as the head sees it: the hull's silhouette along +z (its points' convex
    /// hull in x and y, counter-clockwise), laid at the face's height; for a page to draw.
    pub fn outline(&self) -> Vec<Point3<f64>> {
        let mut xy: Vec<(f64, f64)> = self.hull.points().iter().map(|p| (p.x, p.y)).collect();
        xy.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        xy.dedup();
        // Andrew's monotone chain: the lower hull left to right, the upper right to left.
        let turn = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
            (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
        };
        let mut chain: Vec<(f64, f64)> = Vec::with_capacity(2 * xy.len());
        for pass in [xy.clone(), xy.iter().rev().copied().collect()] {
            let start = chain.len();
            for p in pass {
                while chain.len() >= start + 2
                    && turn(chain[chain.len() - 2], chain[chain.len() - 1], p) <= 0.0
                {
                    chain.pop();
                }
                chain.push(p);
            }
            // Each pass ends where the other starts.
            chain.pop();
        }
        chain
            .into_iter()
            .map(|(x, y)| Point3::new(x, y, self.z_max))
            .collect()
    }
}

/// Points on the hull's triangles (`points`, `triangles`): candidates every
/// [`CANDIDATE_SPACING_M`] on each triangle and along the face's rim, the hull's corners first,
/// thinned so that no two kept are nearer than their class's spacing ([`RIM_SPACING_M`],
/// [`FACE_SPACING_M`], [`OTHER_SPACING_M`]; each candidate within its spacing of a kept one,
/// so the surface is covered to that plus the candidates' own spacing), the spacings widened
/// together until at most [`MAX_SAMPLES`] remain.
fn spread(points: &[Point3<f64>], triangles: &[[u32; 3]]) -> Vec<Point3<f64>> {
    // (point, class) in the order they are offered: corners, the rim, the face, the rest, so
    // the rim and the face are kept before what lies behind them.
    let mut facing_corner = vec![false; points.len()];
    let mut edges: std::collections::HashMap<(u32, u32), (u8, u8)> =
        std::collections::HashMap::new();
    let (mut face, mut rest) = (Vec::new(), Vec::new());
    for t in triangles {
        let [a, b, c] = t.map(|i| points[i as usize]);
        let Some(n) = (b - a).cross(&(c - a)).try_normalize(1e-18) else {
            continue;
        };
        let towards = n.z >= FACING_COS;
        for k in 0..3 {
            let (i, j) = (t[k], t[(k + 1) % 3]);
            let e = edges.entry((i.min(j), i.max(j))).or_default();
            e.0 += u8::from(towards);
            e.1 += 1;
            facing_corner[i as usize] |= towards;
        }
        let class = if towards { Class::Face } else { Class::Other };
        let out = if towards { &mut face } else { &mut rest };
        lattice(a, b, c, |p| out.push((p, class)));
    }
    let mut rim_edges: Vec<_> = edges
        .into_iter()
        .filter(|(_, (facing, all))| *facing == 1 && *all == 2)
        .map(|(e, _)| e)
        .collect();
    rim_edges.sort_unstable();
    let mut candidates: Vec<(Point3<f64>, Class)> = points
        .iter()
        .zip(&facing_corner)
        .map(|(p, &f)| (*p, if f { Class::Rim } else { Class::Other }))
        .collect();
    for (i, j) in rim_edges {
        let (a, b) = (points[i as usize], points[j as usize]);
        let k = ((b - a).norm() / CANDIDATE_SPACING_M).ceil().max(1.0) as usize;
        candidates.extend((0..=k).map(|m| (a + (b - a) * (m as f64 / k as f64), Class::Rim)));
    }
    candidates.extend(face);
    candidates.extend(rest);
    let mut scale = 1.0;
    loop {
        let kept = thin(&candidates, scale);
        if kept.len() <= MAX_SAMPLES {
            return kept;
        }
        scale *= 1.1;
    }
}

/// What part of the hull a candidate lies on, which sets its spacing.
#[derive(Debug, Clone, Copy)]
enum Class {
    Rim,
    Face,
    Other,
}

impl Class {
    fn spacing(self) -> f64 {
        match self {
            Self::Rim => RIM_SPACING_M,
            Self::Face => FACE_SPACING_M,
            Self::Other => OTHER_SPACING_M,
        }
    }
}

/// Points every [`CANDIDATE_SPACING_M`] or closer over the triangle `abc`.
fn lattice(a: Point3<f64>, b: Point3<f64>, c: Point3<f64>, mut out: impl FnMut(Point3<f64>)) {
    let longest = (b - a).norm().max((c - b).norm()).max((a - c).norm());
    let k = (longest / CANDIDATE_SPACING_M).ceil().max(1.0) as usize;
    for i in 0..=k {
        for j in 0..=(k - i) {
            let (u, v) = (i as f64 / k as f64, j as f64 / k as f64);
            out(a + (b - a) * u + (c - a) * v);
        }
    }
}

/// Candidates every this far on the hull's triangles, m.
const CANDIDATE_SPACING_M: f64 = 0.0015;

/// The candidates kept in order, each unless a kept one is nearer than its class's spacing
/// times `scale`. A grid of cells one widest spacing across finds the kept ones near a
/// candidate.
fn thin(candidates: &[(Point3<f64>, Class)], scale: f64) -> Vec<Point3<f64>> {
    let cell = OTHER_SPACING_M.max(FACE_SPACING_M).max(RIM_SPACING_M) * scale;
    let key = |p: &Point3<f64>| {
        (
            (p.x / cell).floor() as i64,
            (p.y / cell).floor() as i64,
            (p.z / cell).floor() as i64,
        )
    };
    let mut grid: std::collections::HashMap<(i64, i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    let mut kept: Vec<Point3<f64>> = Vec::new();
    for (p, class) in candidates {
        let spacing = class.spacing() * scale;
        let (x, y, z) = key(p);
        let near = (-1..=1).any(|dx| {
            (-1..=1).any(|dy| {
                (-1..=1).any(|dz| {
                    grid.get(&(x + dx, y + dy, z + dz))
                        .is_some_and(|v| v.iter().any(|&i| (kept[i] - p).norm() < spacing))
                })
            })
        });
        if !near {
            grid.entry((x, y, z)).or_default().push(kept.len());
            kept.push(*p);
        }
    }
    kept
}

#[cfg(test)]
pub(crate) mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    /// A box 0.2 × 0.1 × 0.02 m behind the coil's face, wound outward.
    pub(crate) fn slab() -> crate::mesh::Mesh {
        let (x, y, z0, z1) = (0.1, 0.05, -0.021, -0.001);
        let vertices = vec![
            Point3::new(-x, -y, z0),
            Point3::new(x, -y, z0),
            Point3::new(x, y, z0),
            Point3::new(-x, y, z0),
            Point3::new(-x, -y, z1),
            Point3::new(x, -y, z1),
            Point3::new(x, y, z1),
            Point3::new(-x, y, z1),
        ];
        let triangles = vec![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
        ];
        crate::mesh::Mesh {
            vertices,
            triangles,
        }
    }

    #[test]
    fn a_box_s_hull_is_itself_and_its_samples_cover_it() {
        let c = Casing::new(&slab().vertices, "slab.stl").unwrap();
        assert_eq!(c.z_span(), (-0.021, -0.001));
        assert!(
            (c.extent() - (0.1f64.powi(2) + 0.05f64.powi(2) + 0.021f64.powi(2)).sqrt()).abs()
                < 1e-12
        );
        let s = c.samples();
        assert!(s.len() <= MAX_SAMPLES && s.len() > 100, "{}", s.len());
        // Every sample on the hull's surface, every corner among them.
        assert!(s.iter().all(on_box_surface));
        for v in slab().vertices {
            assert!(s.contains(&v), "{v}");
        }
        // The face (z = −1 mm) covered: no point of it farther than the spacing (and the
        // candidates' own) from a sample.
        for i in 0..=40 {
            for j in 0..=20 {
                let q = Point3::new(
                    -0.1 + 0.2 * i as f64 / 40.0,
                    -0.05 + 0.1 * j as f64 / 20.0,
                    -0.001,
                );
                let near = s
                    .iter()
                    .map(|p| (p - q).norm())
                    .fold(f64::INFINITY, f64::min);
                assert!(near <= FACE_SPACING_M + CANDIDATE_SPACING_M, "{q}: {near}");
            }
        }
    }

    #[test]
    fn a_box_s_outline_is_its_four_corners_at_its_face() {
        let c = Casing::new(&slab().vertices, "slab.stl").unwrap();
        let o = c.outline();
        assert_eq!(
            o,
            vec![
                Point3::new(-0.1, -0.05, -0.001),
                Point3::new(0.1, -0.05, -0.001),
                Point3::new(0.1, 0.05, -0.001),
                Point3::new(-0.1, 0.05, -0.001),
            ]
        );
    }

    fn on_box_surface(p: &Point3<f64>) -> bool {
        let e = 1e-9;
        (p.x.abs() - 0.1).abs() < e
            || (p.y.abs() - 0.05).abs() < e
            || (p.z + 0.021).abs() < e
            || (p.z + 0.001).abs() < e
    }

    #[test]
    fn a_flat_or_broken_casing_is_refused_by_name() {
        let mut flat = slab();
        for v in &mut flat.vertices {
            v.z = 0.0;
        }
        let e = Casing::new(&flat.vertices, "flat.stl")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("flat.stl") && e.contains("encloses no volume"),
            "{e}"
        );
        let mut nan = slab();
        nan.vertices[3].y = f64::NAN;
        let e = Casing::new(&nan.vertices, "nan.stl")
            .unwrap_err()
            .to_string();
        assert!(e.contains("nan.stl") && e.contains("vertex 3"), "{e}");
        let few = crate::mesh::Mesh {
            vertices: slab().vertices[..3].to_vec(),
            triangles: vec![[0, 1, 2]],
        };
        let e = Casing::new(&few.vertices, "few.stl")
            .unwrap_err()
            .to_string();
        assert!(e.contains("3 vertices"), "{e}");
        // Two casings are two, even from one file.
        let (a, b) = (
            Casing::new(&slab().vertices, "a").unwrap(),
            Casing::new(&slab().vertices, "a").unwrap(),
        );
        assert_ne!(a, b);
        assert_eq!(a, a.clone());
    }
}
