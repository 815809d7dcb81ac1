//! A convex hull's support map that climbs its edges instead of scanning every vertex: GJK asks
//! a casing's hull for its farthest point along a direction twenty to forty times a query, and
//! parry's `ConvexPolyhedron` answers each by a scan of all its vertices (the D70's hull: 247).
//! On a convex polyhedron a vertex no neighbour beats along a direction is the farthest of all
//! (the polyhedron lies in the cone its edges span from there), so a greedy climb from a good
//! start ends at the support point after a few steps.

use mocomp_geom::nalgebra::{Point3, Vector3};
use parry3d_f64::shape::SupportMap;

/// The directions whose support vertices are the climb's candidate starts: the cube's faces,
/// edges and corners (26), so a start lies within about 35° of any direction asked.
const START_DIRECTIONS: usize = 26;

/// A convex hull's vertices, their neighbours along its edges, and where to start climbing.
#[derive(Debug, Clone)]
pub(crate) struct Climb {
    points: Vec<Point3<f64>>,
    /// Vertex `i`'s neighbours: `adjacent[first[i]..first[i + 1]]`.
    first: Vec<u32>,
    adjacent: Vec<u32>,
    starts: [u32; START_DIRECTIONS],
}

impl Climb {
    /// The climb over the hull with vertices `points` and triangles `triangles` (a convex
    /// hull's, every vertex on at least one; `points` not empty).
    pub(crate) fn new(points: &[Point3<f64>], triangles: &[[u32; 3]]) -> Self {
        let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); points.len()];
        for t in triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                neighbours[a as usize].push(b);
                neighbours[b as usize].push(a);
            }
        }
        let mut first = Vec::with_capacity(points.len() + 1);
        let mut adjacent = Vec::new();
        for mut n in neighbours {
            n.sort_unstable();
            n.dedup();
            first.push(adjacent.len() as u32);
            adjacent.extend(n);
        }
        first.push(adjacent.len() as u32);
        let mut starts = [0u32; START_DIRECTIONS];
        let mut k = 0;
        for x in -1i32..=1 {
            for y in -1i32..=1 {
                for z in -1i32..=1 {
                    if (x, y, z) == (0, 0, 0) {
                        continue;
                    }
                    let d = Vector3::new(f64::from(x), f64::from(y), f64::from(z));
                    starts[k] = scan(points, &d);
                    k += 1;
                }
            }
        }
        Self {
            points: points.to_vec(),
            first,
            adjacent,
            starts,
        }
    }

    /// The vertex farthest along `dir`: the best start, then up its edges while a neighbour is
    /// farther.
    fn support_vertex(&self, dir: &Vector3<f64>) -> u32 {
        let along = |i: u32| self.points[i as usize].coords.dot(dir);
        let mut at = self.starts[0];
        let mut best = along(at);
        for &s in &self.starts[1..] {
            let d = along(s);
            if d > best {
                (at, best) = (s, d);
            }
        }
        loop {
            let (lo, hi) = (
                self.first[at as usize] as usize,
                self.first[at as usize + 1] as usize,
            );
            let mut next = at;
            for &n in &self.adjacent[lo..hi] {
                let d = along(n);
                if d > best {
                    (next, best) = (n, d);
                }
            }
            if next == at {
                return at;
            }
            at = next;
        }
    }
}

/// The vertex of `points` farthest along `d` (a scan; only to place the starts).
fn scan(points: &[Point3<f64>], d: &Vector3<f64>) -> u32 {
    let mut best = (0, f64::NEG_INFINITY);
    for (i, p) in points.iter().enumerate() {
        let v = p.coords.dot(d);
        if v > best.1 {
            best = (i as u32, v);
        }
    }
    best.0
}

impl SupportMap for Climb {
    fn local_support_point(&self, dir: &Vector3<f64>) -> Point3<f64> {
        self.points[self.support_vertex(dir) as usize]
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use proptest::prelude::*;

    /// A casing-like hull: points on a squashed, lopsided ellipsoid, some on its faces' planes.
    fn hull() -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
        let mut cloud = Vec::new();
        for i in 0..40 {
            for j in 0..20 {
                let (u, v) = (
                    std::f64::consts::TAU * f64::from(i) / 40.0,
                    std::f64::consts::PI * (f64::from(j) + 0.5) / 20.0
                        - std::f64::consts::FRAC_PI_2,
                );
                let x = 0.1 * u.cos() * v.cos();
                cloud.push(Point3::new(
                    if x > 0.0 { x } else { 0.6 * x },
                    0.07 * u.sin() * v.cos(),
                    (0.009 * v.sin()).min(0.006) - 0.01,
                ));
            }
        }
        parry3d_f64::transformation::convex_hull(&cloud)
    }

    proptest! {
        /// The climb ends where a scan of every vertex does (the same value along the
        /// direction: a tie may pick another vertex of the same face).
        #[test]
        fn the_climb_finds_the_scan_s_support_point(
            x in -1.0..1.0f64, y in -1.0..1.0f64, z in -1.0..1.0f64,
        ) {
            let (points, triangles) = hull();
            let climb = Climb::new(&points, &triangles);
            let d = Vector3::new(x, y, z);
            let by_climb = climb.local_support_point(&d).coords.dot(&d);
            let by_scan = points[scan(&points, &d) as usize].coords.dot(&d);
            prop_assert!((by_climb - by_scan).abs() <= 1e-15, "{} {}", by_climb, by_scan);
        }
    }
}
