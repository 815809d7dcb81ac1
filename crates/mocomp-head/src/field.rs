//! The scalp's distance field for the control loop: a regular grid around the head whose every
//! node knows its nearest triangle, so a query is a handful of exact point-to-triangle distances
//! (the triangles its cell's corners know, then a walk across edges to ever nearer ones) rather
//! than a descent through a hierarchy: its cost does not grow with the mesh. The sign comes from
//! angle-weighted pseudo-normals (Bærentzen and Aanæs, 2005), exact for a closed, outward mesh.
//!
//! Building: the nodes next to each triangle are seeded exactly, then eight sweeps (one per
//! octant's order, Zhao's fast sweeping) pass each node the better of its upwind neighbours'
//! triangles. A node's triangle may then be near its nearest rather than it; the query's walk
//! makes the answer exact, except on the surface's medial axis (two parts of the scalp equally
//! near), where two walks are taken; the tests measure it against the BVH everywhere in the grid.

use mocomp_geom::nalgebra::{Point3, Vector3};

/// A mesh's vertices and triangles, as the field reads them.
#[derive(Clone, Copy)]
struct Surface<'a> {
    vertices: &'a [Point3<f64>],
    triangles: &'a [[u32; 3]],
}

/// The grid's spacing, m.
pub const SPACING_M: f64 = 0.0025;
/// How far the interpolated distance can be above the exact one held to ±[`EXACT_BAND_M`], m:
/// the grid's nodes hold that distance, it changes by at most the distance moved, and the
/// weights' mean distance to a cell's corners is at most √3/2 of the spacing (at its centre).
/// (Where the interpolated value less this is above `-EXACT_BAND_M`, it is below the exact
/// distance.)
pub const INTERPOLATION_SLACK_M: f64 = 0.866_026 * SPACING_M;

/// How far the grid reaches beyond the head's box, m (beyond it a query is the BVH's).
pub const MARGIN_M: f64 = 0.04;
/// No triangle: a node beyond the band.
const NONE: u32 = u32::MAX;
/// Nodes nearer the surface than this hold their exact signed distance, m (the coil's sampled
/// query interpolates them; a coil this far from the scalp is clear of any rule's threshold).
pub const EXACT_BAND_M: f64 = 0.03;

/// Which part of a triangle a point is nearest: a vertex, an edge (from vertex k to k+1) or
/// the face.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Feature {
    Vertex(u8),
    Edge(u8),
    Face,
}

/// The point of triangle (a, b, c) nearest `p`, and which feature it lies on (Ericson,
/// Real-Time Collision Detection, 5.1.5).
pub(crate) fn closest_on_triangle(
    p: &Point3<f64>,
    a: &Point3<f64>,
    b: &Point3<f64>,
    c: &Point3<f64>,
) -> (Point3<f64>, Feature) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (*a, Feature::Vertex(0));
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (*b, Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, Feature::Edge(0));
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (*c, Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, Feature::Edge(1));
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (a + ab * v + ac * w, Feature::Face)
}

/// Which field this code builds of a mesh: part of the key a field is kept on disk under
/// (`mocomp-app`'s head cache), so a field built by other code is never read back as this
/// code's. Raise it with any change to what [`DistanceField::new`] computes for the same mesh.
pub const FIELD_REVISION: u32 = 1;

/// What the field's sweeps computed: the grid and each node's triangle and value. Kept, it builds
/// the same field again without sweeping ([`DistanceField::with_grid`]).
#[derive(Debug, Clone, PartialEq)]
pub struct FieldGrid {
    /// The grid's first node, m.
    pub origin: [f64; 3],
    /// Nodes along x, y and z.
    pub dims: [usize; 3],
    /// Per node (x fastest): its triangle, or `u32::MAX` for none.
    pub nearest: Vec<u32>,
    /// Per node: its signed distance held to ±[`EXACT_BAND_M`], m.
    pub values: Vec<f32>,
    /// See [`DistanceField::lipschitz`].
    pub lipschitz: f64,
}

/// The mesh's distance field.
#[derive(Debug, Clone)]
pub struct DistanceField {
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    /// Angle-weighted pseudo-normal per vertex.
    vertex_normals: Vec<Vector3<f64>>,
    /// Per triangle, per edge k (k to k+1): the sum of the two faces' normals.
    edge_normals: Vec<[Vector3<f64>; 3]>,
    face_normals: Vec<Vector3<f64>>,
    /// Per triangle, the triangle across each edge (NONE at a border).
    across: Vec<[u32; 3]>,
    origin: Point3<f64>,
    dims: [usize; 3],
    /// Per node: its nearest triangle (or one near it).
    nearest: Vec<u32>,
    /// Per node: its signed distance, exact within [`EXACT_BAND_M`] of the surface and held at
    /// ±[`EXACT_BAND_M`] beyond it (where the distance to its triangle, which the sweep made
    /// near its nearest, is at least the band), for the interpolated query.
    values: Vec<f32>,
    /// How fast the interpolated value can change, per metre moved (see [`Self::lipschitz`]).
    lipschitz: f64,
}

impl DistanceField {
    /// The field of `mesh` (closed, outward, one shell: a repaired mesh), built on the threads
    /// this machine has.
    pub fn new(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Self {
        let mut field = Self::unswept(vertices, triangles);
        field.seed();
        field.sweep();
        field.values = field.node_values();
        field.lipschitz = field.measured_lipschitz();
        field
    }

    /// The field of the mesh with its grid as an earlier [`Self::new`] of the same mesh computed
    /// it (kept: [`Self::grid`]); `None` when the grid is not one of this mesh (another box, a
    /// node count that does not match, a triangle it does not have, a value out of the band or
    /// not a number), for the caller to build the field anew.
    pub fn with_grid(
        vertices: &[Point3<f64>],
        triangles: &[[u32; 3]],
        grid: FieldGrid,
    ) -> Option<Self> {
        let mut field = Self::unswept(vertices, triangles);
        let band = EXACT_BAND_M as f32;
        let fits = grid.origin == <[f64; 3]>::from(field.origin.coords)
            && grid.dims == field.dims
            && grid.nearest.len() == field.nearest.len()
            && grid.values.len() == field.nearest.len()
            && grid
                .nearest
                .iter()
                .all(|&t| t == NONE || (t as usize) < triangles.len())
            && grid.values.iter().all(|v| v.abs() <= band)
            && !grid.lipschitz.is_nan()
            && grid.lipschitz > 0.0;
        if !fits {
            return None;
        }
        field.nearest = grid.nearest;
        field.values = grid.values;
        field.lipschitz = grid.lipschitz;
        Some(field)
    }

    /// What the sweeps computed, to keep.
    pub fn grid(&self) -> FieldGrid {
        FieldGrid {
            origin: self.origin.coords.into(),
            dims: self.dims,
            nearest: self.nearest.clone(),
            values: self.values.clone(),
            lipschitz: self.lipschitz,
        }
    }

    /// The field's mesh, normals, adjacency and grid laid out, its nodes not yet swept.
    fn unswept(vertices: &[Point3<f64>], triangles: &[[u32; 3]]) -> Self {
        let mesh = &Surface {
            vertices,
            triangles,
        };
        let (vertex_normals, edge_normals, face_normals) = pseudo_normals(mesh);
        let b = crate::shape::Aabb::around(vertices).unwrap_or(crate::shape::Aabb {
            min: Point3::origin(),
            max: Point3::origin(),
        });
        let margin = MARGIN_M;
        let origin = b.min - Vector3::repeat(margin);
        let size = b.max - b.min + Vector3::repeat(2.0 * margin);
        let dims = [0, 1, 2].map(|k| (size[k] / SPACING_M).ceil() as usize + 1);
        let across = adjacency(mesh);
        Self {
            across,
            vertices: vertices.to_vec(),
            triangles: triangles.to_vec(),
            vertex_normals,
            edge_normals,
            face_normals,
            origin,
            dims,
            nearest: vec![NONE; dims[0] * dims[1] * dims[2]],
            values: Vec::new(),
            lipschitz: f64::INFINITY,
        }
    }

    /// The steepest the interpolated value gets: within a cell, its slope along an axis is a
    /// weighted mean of the differences between neighbouring nodes along that axis, so the
    /// largest of those differences (per axis, over the grid) bounds its gradient. Held nodes
    /// are samples of the distance held to the band, which changes no faster than the point
    /// moves: about √3. Infinite where the grid's outermost nodes are not held at the band (the
    /// value beyond the grid), so nothing leans on a bound that does not hold there.
    fn measured_lipschitz(&self) -> f64 {
        let [nx, ny, nz] = self.dims;
        let band = EXACT_BAND_M as f32;
        let mut steepest = [0.0f32; 3];
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    let at = self.index(i, j, k);
                    let v = self.values[at];
                    let outermost =
                        i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny || k + 1 == nz;
                    if outermost && v != band {
                        return f64::INFINITY;
                    }
                    // The next node along each axis, where there is one.
                    let next = [(i + 1 < nx, 1), (j + 1 < ny, nx), (k + 1 < nz, nx * ny)];
                    for (axis, (has, step)) in next.into_iter().enumerate() {
                        if has {
                            steepest[axis] = steepest[axis].max((self.values[at + step] - v).abs());
                        }
                    }
                }
            }
        }
        let [x, y, z] = steepest.map(|d| f64::from(d) / SPACING_M);
        (x * x + y * y + z * z).sqrt()
    }

    /// Every node's signed distance (see `values`), on the threads this machine has.
    fn node_values(&self) -> Vec<f32> {
        let threads = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .min(8);
        let per = self.nearest.len().div_ceil(threads).max(1);
        let [nx, ny, _] = self.dims;
        std::thread::scope(|s| {
            let handles: Vec<_> = self
                .nearest
                .chunks(per)
                .enumerate()
                .map(|(c, chunk)| {
                    let h = s.spawn(move || {
                        chunk
                            .iter()
                            .enumerate()
                            .map(|(o, &t)| {
                                if t == NONE {
                                    return EXACT_BAND_M as f32;
                                }
                                let at = c * per + o;
                                let p = self.node(at % nx, (at / nx) % ny, at / (nx * ny));
                                let d = self.distance_to(&p, t);
                                let t = if d < EXACT_BAND_M {
                                    self.walk(&p, d, t).1
                                } else {
                                    t
                                };
                                // Beyond the band the distance to its triangle is at least the
                                // band's: held there, every node is the exact distance held to
                                // the band, and the interpolation changes no faster than that.
                                self.signed_to(&p, t).clamp(-EXACT_BAND_M, EXACT_BAND_M) as f32
                            })
                            .collect::<Vec<f32>>()
                    });
                    (chunk.len(), h)
                })
                .collect();
            // A thread that failed leaves its nodes "inside": every rule then keeps away.
            handles
                .into_iter()
                .flat_map(|(n, h)| h.join().unwrap_or_else(|_| vec![-EXACT_BAND_M as f32; n]))
                .collect()
        })
    }

    /// The signed distance at `p` interpolated (trilinearly) from the grid's nodes, held to
    /// ±[`EXACT_BAND_M`], or `None` outside the grid: a few nanoseconds, within a fraction of
    /// the spacing of the exact distance where the surface is smooth at the grid's scale (the
    /// sampled coil query ranks its points by it and refines the nearest exactly).
    pub fn interpolated(&self, p: &Point3<f64>) -> Option<f64> {
        let ((i, j, k), f) = self.cell(p)?;
        let (fx, fy, fz) = (f.x, f.y, f.z);
        let [nx, ny, _] = self.dims;
        let at = self.index(i, j, k);
        let (sy, sz) = (nx, nx * ny);
        let v = |o: usize| f64::from(self.values[at + o]);
        let lerp = |a: f64, b: f64, f: f64| a + (b - a) * f;
        let y0 = lerp(lerp(v(0), v(1), fx), lerp(v(sy), v(sy + 1), fx), fy);
        let y1 = lerp(
            lerp(v(sz), v(sz + 1), fx),
            lerp(v(sz + sy), v(sz + sy + 1), fx),
            fy,
        );
        Some(lerp(y0, y1, fz))
    }

    /// How much the interpolated value (taken as [`EXACT_BAND_M`] beyond the grid) can change
    /// per metre a point moves: measured on the nodes when the field is built (about √3; see
    /// `measured_lipschitz`). A value known at one point bounds it at points nearby, which
    /// spares the sampled coil query the samples that cannot be the nearest.
    pub fn lipschitz(&self) -> f64 {
        self.lipschitz
    }

    /// Bytes the field holds.
    pub fn memory_bytes(&self) -> usize {
        self.nearest.len() * 8 + self.vertices.len() * 48 + self.triangles.len() * (12 + 96 + 12)
    }

    /// Grid nodes.
    pub fn nodes(&self) -> usize {
        self.nearest.len()
    }

    fn index(&self, i: usize, j: usize, k: usize) -> usize {
        (k * self.dims[1] + j) * self.dims[0] + i
    }

    fn node(&self, i: usize, j: usize, k: usize) -> Point3<f64> {
        self.origin + Vector3::new(i as f64, j as f64, k as f64) * SPACING_M
    }

    /// Each triangle's own cells: the nodes within a cell of it take it if it is the nearest
    /// yet.
    fn seed(&mut self) {
        let mut dist = vec![f64::INFINITY; self.nearest.len()];
        let cell = |x: f64, k: usize, up: bool| -> usize {
            let v = (x - self.origin[k]) / SPACING_M;
            let v = if up { v.ceil() } else { v.floor() };
            (v.max(0.0) as usize).min(self.dims[k] - 1)
        };
        for (t, tri) in self.triangles.iter().enumerate() {
            let [a, b, c] = tri.map(|i| self.vertices[i as usize]);
            let lo = a.inf(&b).inf(&c) - Vector3::repeat(SPACING_M);
            let hi = a.sup(&b).sup(&c) + Vector3::repeat(SPACING_M);
            for k in cell(lo.z, 2, false)..=cell(hi.z, 2, true) {
                for j in cell(lo.y, 1, false)..=cell(hi.y, 1, true) {
                    for i in cell(lo.x, 0, false)..=cell(hi.x, 0, true) {
                        let p = self.node(i, j, k);
                        let d = (p - closest_on_triangle(&p, &a, &b, &c).0).norm_squared();
                        let at = self.index(i, j, k);
                        if d < dist[at] {
                            dist[at] = d;
                            self.nearest[at] = t as u32;
                        }
                    }
                }
            }
        }
    }

    /// Fast sweeping: in each of the eight orders, every node takes the nearest of its own and
    /// its three upwind neighbours' triangles. The grid is cut into slabs of z, one a thread,
    /// each swept on its own: a node near a cut may keep a triangle near its nearest rather than
    /// it, which the query's walk corrects.
    fn sweep(&mut self) {
        let threads = std::thread::available_parallelism()
            .map_or(1, |n| n.get())
            .min(8);
        let nz = self.dims[2];
        let per = nz.div_ceil(threads);
        let slab = self.dims[0] * self.dims[1];
        let this = &*self;
        let swept: Vec<(usize, Vec<u32>)> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads)
                .map(|t| (t * per, ((t + 1) * per).min(nz)))
                .filter(|(k0, k1)| k0 < k1)
                .map(|(k0, k1)| s.spawn(move || (k0, this.sweep_slab(k0, k1))))
                .collect();
            handles.into_iter().filter_map(|h| h.join().ok()).collect()
        });
        for (k0, nearest) in swept {
            let at = k0 * slab;
            self.nearest[at..at + nearest.len()].copy_from_slice(&nearest);
        }
    }

    /// The eight sweeps over the nodes with k0 ≤ k < k1; their triangles.
    fn sweep_slab(&self, k0: usize, k1: usize) -> Vec<u32> {
        let [nx, ny, _] = self.dims;
        let nz = k1 - k0;
        let local = |i: usize, j: usize, k: usize| (k * ny + j) * nx + i;
        let mut nearest = self.nearest[k0 * nx * ny..k1 * nx * ny].to_vec();
        let mut dist: Vec<f64> = (0..nearest.len())
            .map(|at| {
                let t = nearest[at];
                if t == NONE {
                    f64::INFINITY
                } else {
                    let (i, j, k) = (at % nx, (at / nx) % ny, at / (nx * ny));
                    self.distance_to(&self.node(i, j, k + k0), t)
                }
            })
            .collect();
        let order = |n: usize, up: bool| -> Box<dyn Iterator<Item = usize>> {
            if up {
                Box::new(0..n)
            } else {
                Box::new((0..n).rev())
            }
        };
        let back = |v: usize, up: bool, n: usize| -> Option<usize> {
            if up {
                v.checked_sub(1)
            } else {
                (v + 1 < n).then_some(v + 1)
            }
        };
        for octant in 0..8 {
            let (ux, uy, uz) = (octant & 1 == 0, octant & 2 == 0, octant & 4 == 0);
            for k in order(nz, uz) {
                for j in order(ny, uy) {
                    for i in order(nx, ux) {
                        let at = local(i, j, k);
                        let (mut best, mut best_t) = (dist[at], nearest[at]);
                        let neighbours = [
                            back(i, ux, nx).map(|a| local(a, j, k)),
                            back(j, uy, ny).map(|b| local(i, b, k)),
                            back(k, uz, nz).map(|c| local(i, j, c)),
                        ];
                        let p = self.node(i, j, k + k0);
                        for n in neighbours.into_iter().flatten() {
                            let t = nearest[n];
                            if t == NONE || t == best_t {
                                continue;
                            }
                            let d = self.distance_to(&p, t);
                            if d < best {
                                (best, best_t) = (d, t);
                            }
                        }
                        dist[at] = best;
                        nearest[at] = best_t;
                    }
                }
            }
        }
        nearest
    }

    /// The distance from `p` to triangle `t`.
    fn distance_to(&self, p: &Point3<f64>, t: u32) -> f64 {
        let [a, b, c] = self.triangles[t as usize].map(|i| self.vertices[i as usize]);
        (p - closest_on_triangle(p, &a, &b, &c).0).norm()
    }

    /// From triangle `t` at distance `d`, across edges to ever nearer triangles; the last one.
    fn walk(&self, p: &Point3<f64>, mut d: f64, mut t: u32) -> (f64, u32) {
        // A walk on a closed mesh cannot revisit with a falling distance; the cap only guards
        // against a mesh that was not repaired.
        for _ in 0..256 {
            let mut moved = false;
            for &n in &self.across[t as usize] {
                if n == NONE {
                    continue;
                }
                let dn = self.distance_to(p, n);
                if dn < d {
                    (d, t, moved) = (dn, n, true);
                }
            }
            if !moved {
                break;
            }
        }
        (d, t)
    }

    /// The signed distance from `p` to triangle `t`, signed by the pseudo-normal of the feature
    /// nearest `p`.
    fn signed_to(&self, p: &Point3<f64>, t: u32) -> f64 {
        let tri = self.triangles[t as usize];
        let [a, b, c] = tri.map(|i| self.vertices[i as usize]);
        let (q, feature) = closest_on_triangle(p, &a, &b, &c);
        let n = match feature {
            Feature::Vertex(k) => self.vertex_normals[tri[k as usize] as usize],
            Feature::Edge(k) => self.edge_normals[t as usize][k as usize],
            Feature::Face => self.face_normals[t as usize],
        };
        let off = p - q;
        let d = off.norm();
        if off.dot(&n) < 0.0 { -d } else { d }
    }

    /// The cell `p` is in (its lowest node) and where in it (0 to 1 along each axis), or `None`
    /// outside the grid.
    fn cell(&self, p: &Point3<f64>) -> Option<((usize, usize, usize), Vector3<f64>)> {
        let g = (p - self.origin) / SPACING_M;
        let [nx, ny, nz] = self.dims;
        if !(g.x >= 0.0 && g.y >= 0.0 && g.z >= 0.0)
            || g.x >= (nx - 1) as f64
            || g.y >= (ny - 1) as f64
            || g.z >= (nz - 1) as f64
        {
            return None;
        }
        let (i, j, k) = (g.x as usize, g.y as usize, g.z as usize);
        Some(((i, j, k), g - Vector3::new(i as f64, j as f64, k as f64)))
    }

    /// The signed distance at `p`, or `None` outside the grid.
    pub fn signed_distance(&self, p: &Point3<f64>) -> Option<f64> {
        self.nearest_triangle(p).map(|(d, _)| d)
    }

    /// The signed distance at `p` and the triangle where it is attained, or `None` outside the
    /// grid.
    pub fn nearest_triangle(&self, p: &Point3<f64>) -> Option<(f64, u32)> {
        let ((i, j, k), _) = self.cell(p)?;
        let mut start = [(f64::INFINITY, NONE); 8];
        let mut n_start = 0;
        for (di, dj, dk) in [
            (0, 0, 0),
            (1, 0, 0),
            (0, 1, 0),
            (1, 1, 0),
            (0, 0, 1),
            (1, 0, 1),
            (0, 1, 1),
            (1, 1, 1),
        ] {
            let t = self.nearest[self.index(i + di, j + dj, k + dk)];
            if t == NONE || start[..n_start].iter().any(|s| s.1 == t) {
                continue;
            }
            start[n_start] = (self.distance_to(p, t), t);
            n_start += 1;
        }
        // The corners' triangles are near p's nearest, not always it: from each that could be,
        // walk across edges while the distance falls (on a smooth surface the nearest triangle is
        // the only local minimum; two minima only on the medial axis, and each side's corners
        // seed its own walk).
        let first = start[..n_start]
            .iter()
            .map(|s| s.0)
            .fold(f64::INFINITY, f64::min);
        // Walks from the best candidate, and from any other within a hair of it (p on the
        // medial axis, two parts of the surface equally near).
        let slack = 1e-4;
        let (mut best, mut best_t) = (f64::INFINITY, NONE);
        for &(d0, t0) in &start[..n_start] {
            if d0 > first + slack {
                continue;
            }
            let (d, t) = self.walk(p, d0, t0);
            if d < best {
                (best, best_t) = (d, t);
            }
        }
        (best_t != NONE).then(|| (self.signed_to(p, best_t), best_t))
    }
}

/// The triangle across each edge of each triangle.
fn adjacency(mesh: &Surface<'_>) -> Vec<[u32; 3]> {
    let mut by_edge: std::collections::HashMap<(u32, u32), [u32; 2]> =
        std::collections::HashMap::with_capacity(mesh.triangles.len() * 2);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let e = by_edge.entry((a.min(b), a.max(b))).or_insert([NONE; 2]);
            if e[0] == NONE {
                e[0] = t as u32;
            } else {
                e[1] = t as u32;
            }
        }
    }
    mesh.triangles
        .iter()
        .enumerate()
        .map(|(t, tri)| {
            std::array::from_fn(|k| {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let e = by_edge
                    .get(&(a.min(b), a.max(b)))
                    .copied()
                    .unwrap_or([NONE; 2]);
                if e[0] == t as u32 { e[1] } else { e[0] }
            })
        })
        .collect()
}

/// Angle-weighted vertex normals, edge normals (the sum of the two faces') and face normals.
type Normals = (Vec<Vector3<f64>>, Vec<[Vector3<f64>; 3]>, Vec<Vector3<f64>>);

fn pseudo_normals(mesh: &Surface<'_>) -> Normals {
    let v = &mesh.vertices;
    let faces: Vec<Vector3<f64>> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| v[i as usize]);
            (b - a)
                .cross(&(c - a))
                .try_normalize(1e-300)
                .unwrap_or_else(Vector3::z)
        })
        .collect();
    let mut vertex = vec![Vector3::zeros(); v.len()];
    let mut by_edge: std::collections::HashMap<(u32, u32), Vector3<f64>> =
        std::collections::HashMap::with_capacity(mesh.triangles.len() * 2);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b, c) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
            let e1 = v[b as usize] - v[a as usize];
            let e2 = v[c as usize] - v[a as usize];
            let angle = e1.angle(&e2);
            vertex[a as usize] += faces[t] * angle;
            *by_edge.entry((a.min(b), a.max(b))).or_default() += faces[t];
        }
    }
    let edges = mesh
        .triangles
        .iter()
        .map(|tri| {
            std::array::from_fn(|k| {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                by_edge
                    .get(&(a.min(b), a.max(b)))
                    .copied()
                    .unwrap_or_default()
            })
        })
        .collect();
    (vertex, edges, faces)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::MeshHead;
    use crate::mesh::tests::ellipsoid_mesh;
    use parry3d_f64::query::PointQuery;
    use parry3d_f64::shape::Triangle;
    use proptest::prelude::*;

    proptest! {
        /// The closest point agrees with parry's projection onto the triangle.
        #[test]
        fn the_closest_point_on_a_triangle_is_parrys(
            c in proptest::collection::vec(-1.0..1.0f64, 12),
        ) {
            let pt = |i: usize| Point3::new(c[i], c[i + 1], c[i + 2]);
            let (p, a, b, cc) = (pt(0), pt(3), pt(6), pt(9));
            let (q, _) = closest_on_triangle(&p, &a, &b, &cc);
            let r = Triangle::new(a, b, cc).project_local_point(&p, true).point;
            prop_assert!((q - r).norm() < 1e-9, "{q} {r}");
        }
    }

    /// Everywhere in its grid the field is the mesh's exact signed distance (the BVH's).
    #[test]
    fn the_field_is_the_exact_distance_everywhere_in_its_grid() {
        let radii = Vector3::new(0.075, 0.095, 0.11);
        let mesh = ellipsoid_mesh(&radii, 5);
        let field = DistanceField::new(&mesh.vertices, &mesh.triangles);
        let exact = MeshHead::new(mesh, "e").unwrap();
        let mut rng = mocomp_testkit::SplitMix64(11);
        let mut next = || rng.next_f64() - 0.5;
        let (mut inside, mut outside_grid) = (0, 0);
        for n in 0..4000 {
            let mut p = Point3::new(0.4 * next(), 0.45 * next(), 0.5 * next());
            if n % 2 == 0 {
                // Half of them near the surface, where the loop asks.
                let on = p.coords.normalize().component_mul(&radii);
                p = Point3::from(on * (1.0 + 0.3 * next()));
            }
            let truth = exact.exact(&p);
            match field.signed_distance(&p) {
                Some(d) => {
                    inside += usize::from(d < 0.0);
                    assert!((d - truth).abs() < 1e-9, "{p}: {d} against {truth}");
                }
                None => {
                    outside_grid += 1;
                    assert!(truth > MARGIN_M, "{p}");
                }
            }
        }
        assert!(
            inside > 800 && outside_grid > 100,
            "{inside} {outside_grid}"
        );
    }
}
