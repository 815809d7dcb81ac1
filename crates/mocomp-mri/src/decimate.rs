//! A closed triangle surface brought down to a stated number of triangles by quadric edge
//! collapse (Garland and Heckbert 1997): each edge's cost is the summed squared distance of its
//! merged vertex to the planes of the triangles its ends had; the cheapest goes first.
//!
//! Written here because the one maintained crate for it (`meshopt`, meshoptimizer's simplifier)
//! made edges shared by four triangles on Colin27's scalp, and a head model must stay a closed
//! manifold with an inside. A collapse is made only when it keeps that: the edge's ends share
//! exactly the two neighbours of the triangles on it (the link condition), and no triangle
//! around it turns over or degenerates.

use mocomp_geom::nalgebra::{Matrix3, Matrix4, Vector3, Vector4};

/// The most a triangle's normal may turn in one collapse (cosine of 60°).
const MIN_NORMAL_COS: f64 = 0.5;

/// The shape below which a triangle is a sliver (1 is equilateral; see [`quality`]).
const MIN_QUALITY: f64 = 0.1;

/// A triangle's shape, 4√3·area / (sum of its squared edges): 1 equilateral, 0 degenerate; and
/// its unit normal (zero when degenerate).
fn quality(t: &[Vector3<f64>; 3]) -> (f64, Vector3<f64>) {
    let n = (t[1] - t[0]).cross(&(t[2] - t[0]));
    let edges =
        (t[1] - t[0]).norm_squared() + (t[2] - t[1]).norm_squared() + (t[0] - t[2]).norm_squared();
    let area2 = n.norm();
    if edges <= 0.0 || area2 <= 0.0 {
        return (0.0, Vector3::zeros());
    }
    (2.0 * 3f64.sqrt() * area2 / edges, n / area2)
}

/// The most neighbours a vertex may gather: flat regions would otherwise collapse into a few
/// fans of slivers (and each collapse there would requeue hundreds of edges).
const MAX_VALENCE: usize = 12;

/// The surface as it is collapsed.
struct Collapser {
    positions: Vec<Vector3<f64>>,
    quadrics: Vec<Matrix4<f64>>,
    triangles: Vec<[u32; 3]>,
    alive: Vec<bool>,
    /// Each vertex's triangles (dead ones pruned as met).
    around: Vec<Vec<u32>>,
    /// Each triangle's edges' costs (edge j runs from corner j to corner j + 1).
    cost: Vec<[f64; 3]>,
    /// Triangles changed in this pass: left alone until the next, so one pass's collapses do
    /// not build on each other.
    dirty: Vec<bool>,
    live: usize,
}

impl Collapser {
    fn new(vertices: &[[f64; 3]], triangles: &[[u32; 3]]) -> Self {
        let positions: Vec<Vector3<f64>> = vertices.iter().map(|v| Vector3::from(*v)).collect();
        let mut quadrics = vec![Matrix4::zeros(); positions.len()];
        let mut around = vec![Vec::new(); positions.len()];
        for (t, tri) in triangles.iter().enumerate() {
            let [a, b, c] = tri.map(|v| positions[v as usize]);
            let n = (b - a).cross(&(c - a));
            let area2 = n.norm();
            if area2 > 0.0 {
                let n = n / area2;
                let plane = Vector4::new(n.x, n.y, n.z, -n.dot(&a));
                // Weighted by area, so a sliver counts as little as it covers.
                let q = plane * plane.transpose() * (area2 / 2.0);
                for &v in tri {
                    quadrics[v as usize] += q;
                }
            }
            for &v in tri {
                around[v as usize].push(t as u32);
            }
        }
        let mut c = Self {
            positions,
            quadrics,
            alive: vec![true; triangles.len()],
            triangles: triangles.to_vec(),
            around,
            cost: vec![[0.0; 3]; triangles.len()],
            dirty: vec![false; triangles.len()],
            live: triangles.len(),
        };
        for t in 0..triangles.len() {
            c.update_cost(t);
        }
        c
    }

    fn update_cost(&mut self, t: usize) {
        let tri = self.triangles[t];
        self.cost[t] = std::array::from_fn(|j| self.placement(tri[j], tri[(j + 1) % 3]).1);
    }

    /// `v`'s neighbours, sorted, into `out`.
    fn neighbours(&self, v: u32, out: &mut Vec<u32>) {
        out.clear();
        out.extend(
            self.around[v as usize]
                .iter()
                .filter(|&&t| self.alive[t as usize])
                .flat_map(|&t| self.triangles[t as usize])
                .filter(|&w| w != v),
        );
        out.sort_unstable();
        out.dedup();
    }

    /// Where the merged vertex goes and what it costs: the quadric's minimum when it is well
    /// posed, else the best of the ends and the midpoint.
    fn placement(&self, a: u32, b: u32) -> (Vector3<f64>, f64) {
        let q = self.quadrics[a as usize] + self.quadrics[b as usize];
        let cost = |p: &Vector3<f64>| {
            let h = Vector4::new(p.x, p.y, p.z, 1.0);
            (h.transpose() * q * h)[0].max(0.0)
        };
        let (pa, pb) = (self.positions[a as usize], self.positions[b as usize]);
        let m: Matrix3<f64> = q.fixed_view::<3, 3>(0, 0).into_owned();
        let rhs = -q.fixed_view::<3, 1>(0, 3).into_owned();
        let optimal = m
            .try_inverse()
            .filter(|_| m.determinant().abs() > 1e-12 * m.norm().powi(3).max(1e-300))
            .map(|inv| inv * rhs)
            // A minimum far from the edge is a badly conditioned one.
            .filter(|p| (p - (pa + pb) / 2.0).norm() <= (pa - pb).norm());
        [optimal, Some(pa), Some(pb), Some((pa + pb) / 2.0)]
            .into_iter()
            .flatten()
            .map(|p| (p, cost(&p)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .unwrap_or(((pa + pb) / 2.0, 0.0))
    }

    /// Whether collapsing `drop` into `keep` at `p` keeps a closed manifold with no triangle
    /// turned over.
    fn allowed(&self, keep: u32, drop: u32, p: &Vector3<f64>, scratch: &mut [Vec<u32>; 2]) -> bool {
        let [nk, nd] = scratch;
        self.neighbours(keep, nk);
        self.neighbours(drop, nd);
        let shared = nk.iter().filter(|v| nd.binary_search(v).is_ok()).count();
        // The merged vertex's neighbours: both rings less the two shared and the two ends.
        if shared != 2 || nk.len() < 3 || nd.len() < 3 || nk.len() + nd.len() - 4 > MAX_VALENCE {
            return false;
        }
        // The surface's side here: a sliver's own normal is noise, the ring's is not.
        let ring: Vector3<f64> = [keep, drop]
            .iter()
            .flat_map(|&v| self.around[v as usize].iter())
            .filter(|&&t| self.alive[t as usize])
            .map(|&t| {
                let [a, b, c] = self.triangles[t as usize].map(|w| self.positions[w as usize]);
                (b - a).cross(&(c - a))
            })
            .sum();
        for &v in &[keep, drop] {
            for &t in &self.around[v as usize] {
                if !self.alive[t as usize] {
                    continue;
                }
                let tri = self.triangles[t as usize];
                if tri.contains(&keep) && tri.contains(&drop) {
                    continue;
                }
                let before = tri.map(|w| self.positions[w as usize]);
                let after = tri.map(|w| {
                    if w == keep || w == drop {
                        *p
                    } else {
                        self.positions[w as usize]
                    }
                });
                let (q0, n0) = quality(&before);
                let (q1, n1) = quality(&after);
                // Facing away from the surface is a fold; a well-shaped triangle may not turn
                // more than 60°; and no collapse makes a sliver out of a triangle.
                if n1.dot(&ring) <= 0.0
                    || (q0 > MIN_QUALITY && n0.dot(&n1) < MIN_NORMAL_COS)
                    || q1 < MIN_QUALITY.min(q0 / 2.0)
                {
                    return false;
                }
            }
        }
        true
    }

    fn collapse(&mut self, keep: u32, drop: u32, p: Vector3<f64>) {
        let moved = std::mem::take(&mut self.around[drop as usize]);
        for &t in &moved {
            if !self.alive[t as usize] {
                continue;
            }
            let tri = &mut self.triangles[t as usize];
            if tri.contains(&keep) {
                self.alive[t as usize] = false;
                self.live -= 1;
            } else {
                for w in tri.iter_mut() {
                    if *w == drop {
                        *w = keep;
                    }
                }
                self.around[keep as usize].push(t);
            }
        }
        let alive = &self.alive;
        self.around[keep as usize].retain(|&t| alive[t as usize]);
        self.positions[keep as usize] = p;
        let qd = self.quadrics[drop as usize];
        self.quadrics[keep as usize] += qd;
        // Only the edges at `keep` changed cost, each shared by two of its triangles:
        // computed once for each neighbour.
        let mut memo: Vec<(u32, f64)> = Vec::with_capacity(MAX_VALENCE + 2);
        for i in 0..self.around[keep as usize].len() {
            let t = self.around[keep as usize][i] as usize;
            self.dirty[t] = true;
            let tri = self.triangles[t];
            for j in 0..3 {
                let (a, b) = (tri[j], tri[(j + 1) % 3]);
                let other = match (a == keep, b == keep) {
                    (true, _) => b,
                    (_, true) => a,
                    _ => continue,
                };
                let cost = match memo.iter().find(|m| m.0 == other) {
                    Some(m) => m.1,
                    None => {
                        let c = self.placement(a, b).1;
                        memo.push((other, c));
                        c
                    }
                };
                self.cost[t][j] = cost;
            }
        }
    }

    /// One pass: every clean triangle with an edge at or below `threshold` collapses its
    /// cheapest such edge when that is allowed. Returns the collapses made.
    fn pass(&mut self, threshold: f64, max_triangles: usize) -> usize {
        self.dirty.iter_mut().for_each(|d| *d = false);
        let mut made = 0;
        let mut scratch = [Vec::new(), Vec::new()];
        for t in 0..self.triangles.len() {
            if self.live <= max_triangles {
                break;
            }
            if !self.alive[t] || self.dirty[t] {
                continue;
            }
            let (j, cost) = (0..3)
                .map(|j| (j, self.cost[t][j]))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap_or((0, f64::INFINITY));
            if cost > threshold {
                continue;
            }
            let tri = self.triangles[t];
            let (a, b) = (tri[j], tri[(j + 1) % 3]);
            let (p, _) = self.placement(a, b);
            if self.allowed(a, b, &p, &mut scratch) {
                self.collapse(a, b, p);
                made += 1;
            }
        }
        made
    }
}

/// Passes before giving up on reaching the size asked for (each removes a good share).
const MAX_PASSES: usize = 200;

/// `triangles` over `vertices` (a closed, consistently wound manifold) collapsed to at most
/// `max_triangles`, or as near as the surface allows while staying one. Returns the new vertices
/// (unused ones dropped) and triangles.
///
/// Cheapest first, in passes rather than through a priority queue: each pass takes the edges
/// at or below the cost of the `n`-th cheapest triangle, `n` the triangles still to go (times a
/// reach that doubles whenever most of those were refused), and collapses those whose
/// triangles this pass has not touched yet. A queue keyed on cost spent
/// most of its time on entries gone stale (9 s on Colin27's 1.2 M triangles; these passes take
/// a fraction of that).
pub fn decimate(
    vertices: &[[f64; 3]],
    triangles: &[[u32; 3]],
    max_triangles: usize,
) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut c = Collapser::new(vertices, triangles);
    let mut reach = 1usize;
    for _ in 0..MAX_PASSES {
        if c.live <= max_triangles {
            break;
        }
        let mut least: Vec<f64> = (0..c.triangles.len())
            .filter(|&t| c.alive[t])
            .map(|t| c.cost[t].iter().copied().fold(f64::INFINITY, f64::min))
            .collect();
        let needed = c.live - max_triangles;
        let n = needed.saturating_mul(reach).min(least.len() - 1);
        let threshold = *least.select_nth_unstable_by(n, |a, b| a.total_cmp(b)).1;
        let made = c.pass(threshold, max_triangles);
        if made == 0 && n == least.len() - 1 {
            // Nothing more can go without breaking the surface.
            break;
        }
        // Most of the cheapest were refused: look further up the costs next time.
        if 2 * made * 4 < needed {
            reach *= 2;
        }
    }
    compact(&c)
}

/// The live triangles over the vertices they use, renumbered.
fn compact(c: &Collapser) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut index = vec![u32::MAX; c.positions.len()];
    let mut vertices = Vec::new();
    let mut triangles = Vec::with_capacity(c.live);
    for (t, tri) in c.triangles.iter().enumerate() {
        if !c.alive[t] {
            continue;
        }
        triangles.push(tri.map(|v| {
            if index[v as usize] == u32::MAX {
                index[v as usize] = vertices.len() as u32;
                let p = c.positions[v as usize];
                vertices.push([p.x, p.y, p.z]);
            }
            index[v as usize]
        }));
    }
    (vertices, triangles)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use std::collections::HashMap;

    /// A UV sphere of radius `r`: closed, outward.
    fn sphere(r: f64, rings: usize, segments: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let mut v = vec![[0.0, 0.0, r]];
        for i in 1..rings {
            let th = std::f64::consts::PI * i as f64 / rings as f64;
            for j in 0..segments {
                let ph = 2.0 * std::f64::consts::PI * j as f64 / segments as f64;
                v.push([
                    r * th.sin() * ph.cos(),
                    r * th.sin() * ph.sin(),
                    r * th.cos(),
                ]);
            }
        }
        v.push([0.0, 0.0, -r]);
        let last = (v.len() - 1) as u32;
        let at = |i: usize, j: usize| (1 + (i - 1) * segments + j % segments) as u32;
        let mut t = Vec::new();
        for j in 0..segments {
            t.push([0, at(1, j), at(1, j + 1)]);
            t.push([last, at(rings - 1, j + 1), at(rings - 1, j)]);
        }
        for i in 1..rings - 1 {
            for j in 0..segments {
                t.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                t.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        (v, t)
    }

    /// Every edge is used once each way: closed, manifold, consistently wound.
    fn assert_closed_manifold(t: &[[u32; 3]]) {
        let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
        for tri in t {
            for (a, b) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
                *edges.entry((a, b)).or_default() += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1, "edge {a}-{b} used {n} times one way");
            assert_eq!(edges.get(&(b, a)), Some(&1), "edge {a}-{b} has no twin");
        }
    }

    #[test]
    fn a_sphere_decimated_stays_a_closed_sphere() {
        let (v, t) = sphere(50.0, 60, 120);
        assert_closed_manifold(&t);
        let (v2, t2) = decimate(&v, &t, 2000);
        assert!(t2.len() <= 2000 && t2.len() > 1900, "{}", t2.len());
        assert_closed_manifold(&t2);
        // Euler characteristic of a sphere: V − E + F = 2.
        assert_eq!(
            v2.len() as i64 - (t2.len() * 3 / 2) as i64 + t2.len() as i64,
            2
        );
        for p in &v2 {
            let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
            assert!((r - 50.0).abs() < 1.0, "{r}");
        }
    }

    #[test]
    fn a_sphere_decimated_hard_stays_a_sphere() {
        let (v, t) = sphere(50.0, 60, 120);
        for target in [1000, 300, 100] {
            let (v2, t2) = decimate(&v, &t, target);
            assert_closed_manifold(&t2);
            let worst = v2
                .iter()
                .map(|p| ((p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() - 50.0).abs())
                .fold(0.0, f64::max);
            assert!(t2.len() <= target, "{target}: {}", t2.len());
            assert!(worst < 5.0, "{target}: a vertex {worst} off the sphere");
        }
    }

    #[test]
    fn asking_for_more_triangles_than_there_are_changes_nothing() {
        let (v, t) = sphere(1.0, 8, 16);
        let (v2, t2) = decimate(&v, &t, 10_000);
        assert_eq!((v2.len(), t2.len()), (v.len(), t.len()));
    }
}
