//! The head as the patient's own scalp: a closed triangle mesh behind a bounding-volume
//! hierarchy (parry's), with pseudo-normals for inside and outside.
//!
//! Two structures, measured against each other (`cargo bench -p mocomp-head`): parry's BVH is
//! exact everywhere but its point query grows with the mesh (2 µs at 4 k triangles, 19 µs at
//! 260 k) and its own cylinder-against-mesh distance is far too slow for the loop (milliseconds;
//! the exact clearance here, on the triangles that can be nearest, is tens of microseconds:
//! still for measuring); the [`DistanceField`] answers anywhere in its grid in one to two
//! microseconds whatever the mesh's size, and its interpolated values rank the coil's sampled
//! points in nanoseconds ([`crate::sampled`]). The BVH stays for ray casts, the exact coil
//! clearance (to measure by) and points beyond the grid.

use crate::cut::ScanCut;
use crate::error::HeadError;
use crate::field::{DistanceField, FieldGrid};
use crate::radial::RadialMap;
use crate::shape::{Aabb, CoilSolid, HeadShape, Known, RayHit, SurfacePoint};
use mocomp_geom::nalgebra::{Isometry3, Point3, Unit, Vector3};
use parry3d_f64::query::{PointQueryWithLocation, Ray, RayCast};
use parry3d_f64::shape::{TriMesh, TriMeshFlags};

/// A triangle mesh: vertices (metres) and triangles (indices into them, wound
/// counter-clockwise seen from outside once repaired).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// The vertices.
    pub vertices: Vec<Point3<f64>>,
    /// The triangles.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Every point moved by `to_from_mesh`.
    pub fn transformed(mut self, to_from_mesh: &Isometry3<f64>) -> Self {
        for v in &mut self.vertices {
            *v = to_from_mesh * *v;
        }
        self
    }

    /// Every coordinate multiplied by `s` (a unit conversion).
    pub fn scaled(mut self, s: f64) -> Self {
        for v in &mut self.vertices {
            v.coords *= s;
        }
        self
    }

    /// The box around the vertices.
    pub fn bounds(&self) -> Option<Aabb> {
        Aabb::around(&self.vertices)
    }

    /// Each triangle cut into four at its edges' midpoints (shared midpoints once): the same
    /// surface with four times the triangles, for measuring what size costs.
    pub fn subdivided(&self) -> Self {
        let mut vertices = self.vertices.clone();
        let mut mid = std::collections::HashMap::new();
        let mut at = |a: u32, b: u32, vertices: &mut Vec<Point3<f64>>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                let p = nalgebra_mid(&vertices[a as usize], &vertices[b as usize]);
                vertices.push(p);
                (vertices.len() - 1) as u32
            })
        };
        let mut triangles = Vec::with_capacity(self.triangles.len() * 4);
        for &[a, b, c] in &self.triangles {
            let ab = at(a, b, &mut vertices);
            let bc = at(b, c, &mut vertices);
            let ca = at(c, a, &mut vertices);
            triangles.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        Self {
            vertices,
            triangles,
        }
    }
}

impl Mesh {
    /// Each triangle split in three at its centroid: the same surface with three times the
    /// triangles (4,062 → 109,674 in three splits), for measuring what a clinical scalp's size
    /// costs.
    pub fn split_at_centroids(&self) -> Self {
        let mut vertices = self.vertices.clone();
        let mut triangles = Vec::with_capacity(self.triangles.len() * 3);
        for &[a, b, c] in &self.triangles {
            let m = Point3::from(
                (self.vertices[a as usize].coords
                    + self.vertices[b as usize].coords
                    + self.vertices[c as usize].coords)
                    / 3.0,
            );
            let i = vertices.len() as u32;
            vertices.push(m);
            triangles.extend([[a, b, i], [b, c, i], [c, a, i]]);
        }
        Self {
            vertices,
            triangles,
        }
    }

    /// A coarser copy for drawing, at most about `max_triangles`: vertices clustered on a grid
    /// (each cell's vertices become their mean), triangles whose corners share a cell dropped,
    /// the cell grown until few enough remain. Not a surface to compute with.
    pub fn decimated(&self, max_triangles: usize) -> Self {
        let Some(b) = self.bounds() else {
            return Self::default();
        };
        let mut cell = b.extent() / 64.0;
        loop {
            let out = self.clustered(&b.min, cell);
            if out.triangles.len() <= max_triangles || cell > b.extent() {
                return out;
            }
            cell *= 1.25;
        }
    }

    fn clustered(&self, origin: &Point3<f64>, cell: f64) -> Self {
        let mut index = std::collections::HashMap::new();
        let mut sums: Vec<(Vector3<f64>, f64)> = Vec::new();
        let map: Vec<u32> = self
            .vertices
            .iter()
            .map(|p| {
                let k = ((p - origin) / cell).map(|x| x.floor() as i64);
                let at = *index.entry((k.x, k.y, k.z)).or_insert_with(|| {
                    sums.push((Vector3::zeros(), 0.0));
                    (sums.len() - 1) as u32
                });
                let s = &mut sums[at as usize];
                s.0 += p.coords;
                s.1 += 1.0;
                at
            })
            .collect();
        let mut seen = std::collections::HashSet::new();
        let triangles = self
            .triangles
            .iter()
            .map(|t| t.map(|v| map[v as usize]))
            .filter(|[a, b, c]| a != b && b != c && a != c)
            .filter(|t| {
                let mut k = *t;
                k.sort_unstable();
                seen.insert(k)
            })
            .collect();
        Self {
            vertices: sums.iter().map(|(s, n)| Point3::from(s / *n)).collect(),
            triangles,
        }
    }
}

fn nalgebra_mid(a: &Point3<f64>, b: &Point3<f64>) -> Point3<f64> {
    Point3::from((a.coords + b.coords) / 2.0)
}

/// The patient's scalp as a head shape. Build it from a repaired mesh ([`crate::repair`]):
/// closed, outward, one shell.
pub struct MeshHead {
    mesh: TriMesh,
    field: DistanceField,
    radial: RadialMap,
    bounds: Aabb,
    triangles: usize,
    /// Which head this is, among those this process built: what a sampled clearance's memory
    /// checks it is asked about the head it remembers.
    id: u64,
    /// Where the scan it was segmented from ends inside the head (the model is flat there).
    cuts: Vec<ScanCut>,
}

/// The next head's [`MeshHead::id`].
static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

impl std::fmt::Debug for MeshHead {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeshHead")
            .field("vertices", &self.mesh.vertices().len())
            .field("triangles", &self.triangles)
            .field("bounds", &self.bounds)
            .finish()
    }
}

impl MeshHead {
    /// The head of `mesh` (head frame, metres), read from `file`.
    pub fn new(mesh: Mesh, file: &str) -> Result<Self, HeadError> {
        Self::build(mesh, file, None).map(|(head, _)| head)
    }

    /// [`Self::new`] with its distance field's grid as an earlier build of the same mesh left
    /// it ([`Self::field_grid`], kept by the caller), which spares the field's sweeps (most of
    /// the start-up); the field is built anew when the grid is not this mesh's. Whether the
    /// grid was taken.
    pub fn with_field_grid(
        mesh: Mesh,
        file: &str,
        grid: FieldGrid,
    ) -> Result<(Self, bool), HeadError> {
        Self::build(mesh, file, Some(grid))
    }

    /// The grid its distance field computed, to keep.
    pub fn field_grid(&self) -> FieldGrid {
        self.field.grid()
    }

    fn build(mesh: Mesh, file: &str, grid: Option<FieldGrid>) -> Result<(Self, bool), HeadError> {
        let bounds = mesh.bounds().ok_or_else(|| HeadError::Empty {
            file: file.into(),
            what: "no vertices".into(),
        })?;
        let triangles = mesh.triangles.len();
        let kept = grid.and_then(|g| DistanceField::with_grid(&mesh.vertices, &mesh.triangles, g));
        let taken = kept.is_some();
        let field = kept.unwrap_or_else(|| DistanceField::new(&mesh.vertices, &mesh.triangles));
        let mesh = TriMesh::with_flags(mesh.vertices, mesh.triangles, TriMeshFlags::ORIENTED)
            .map_err(|e| HeadError::Shape {
                file: file.into(),
                what: format!("the mesh cannot be indexed: {e}"),
            })?;
        // The radial map about the box's centre: a ray from beyond the head back towards the
        // centre first meets the head at its farthest point on that side.
        let centre = nalgebra_mid(&bounds.min, &bounds.max);
        let far = (bounds.max - bounds.min).norm() + 0.01;
        let radial = RadialMap::new(centre, |d| {
            let ray = Ray::new(centre + d * far, -d);
            mesh.cast_local_ray(&ray, far, false).map(|t| far - t)
        });
        Ok((
            Self {
                mesh,
                field,
                radial,
                bounds,
                triangles,
                id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
                cuts: Vec::new(),
            },
            taken,
        ))
    }

    /// The same head, knowing where the scan it came from ends inside it (head frame).
    pub fn with_cuts(mut self, cuts: Vec<ScanCut>) -> Self {
        self.cuts = cuts;
        self
    }

    /// Where the scan ends inside the head: the model is flat there, not the patient.
    pub fn cuts(&self) -> &[ScanCut] {
        &self.cuts
    }

    /// The distance field (the sampled coil query reads it).
    pub(crate) fn field(&self) -> &DistanceField {
        &self.field
    }

    /// How fast the distance field's interpolated value can change per metre moved (see
    /// [`DistanceField::lipschitz`]).
    pub fn lipschitz(&self) -> f64 {
        self.field.lipschitz()
    }

    /// The distance field's interpolated value at `p` (held to ±[`crate::field::EXACT_BAND_M`]),
    /// or `None` beyond its grid: the value the sampled coil query ranks its points by.
    pub fn field_value(&self, p: &Point3<f64>) -> Option<f64> {
        self.field.interpolated(p)
    }

    /// Which head this is among those this process built.
    pub(crate) fn id(&self) -> u64 {
        self.id
    }

    /// Its vertices.
    pub fn vertices(&self) -> &[Point3<f64>] {
        self.mesh.vertices()
    }

    /// Its triangles.
    pub fn triangles(&self) -> &[[u32; 3]] {
        self.mesh.indices()
    }

    /// The memory its vertices, triangles, pseudo-normals and hierarchy hold, bytes (an
    /// estimate from their sizes: 24 bytes a vertex, 12 a triangle, 72 a triangle's normals,
    /// about 64 a hierarchy node, one node a triangle).
    pub fn memory_bytes(&self) -> usize {
        let v = self.mesh.vertices().len();
        v * 24 + self.triangles * (12 + 72 + 64) + self.field.memory_bytes()
    }

    /// The exact signed distance through the BVH (beyond the field's grid, and to check the
    /// field against).
    pub fn exact(&self, p: &Point3<f64>) -> f64 {
        // The variant that reads the pseudo-normals for inside and outside.
        let (proj, _) = self.mesh.project_local_point_and_get_location(p, false);
        let d = (p - proj.point).norm();
        if proj.is_inside { -d } else { d }
    }

    /// What the field knows at `p`, or the box's bound outside its grid.
    fn known(&self, p: &Point3<f64>) -> Known {
        match self.field.signed_distance(p) {
            Some(d) => Known::Exact(d),
            // Beyond the grid (more than its margin from the head's box), the box's distance.
            None => Known::Below(self.bounds.distance(p)),
        }
    }

    /// The outward unit normal of triangle `t`.
    fn face_normal(&self, t: u32) -> Unit<Vector3<f64>> {
        let tri = self.mesh.triangle(t);
        tri.normal().unwrap_or(Vector3::z_axis())
    }
}

impl HeadShape for MeshHead {
    fn signed_distance(&self, p: &Point3<f64>) -> f64 {
        match self.field.signed_distance(p) {
            Some(d) => d,
            None => self.exact(p),
        }
    }

    fn distance_below(&self, p: &Point3<f64>, cutoff: f64) -> f64 {
        // The interpolated field, less what it can err by, spares the exact query for the many
        // points a check only needs to know are far enough (a bound of the exact distance only
        // above the depth the field holds its values to).
        if let Some(v) = self.field.interpolated(p) {
            let bound = v - crate::field::INTERPOLATION_SLACK_M;
            if bound >= cutoff && cutoff > -crate::field::EXACT_BAND_M {
                return bound;
            }
        }
        match self.known(p) {
            Known::Exact(d) => d,
            Known::Below(b) if b >= cutoff => b,
            Known::Below(_) => self.exact(p),
        }
    }

    fn nearest(&self, p: &Point3<f64>) -> SurfacePoint {
        let (proj, (face, _)) = self.mesh.project_local_point_and_get_location(p, false);
        let off = p - proj.point;
        let d = off.norm();
        let sign = if proj.is_inside { -1.0 } else { 1.0 };
        let normal = Unit::try_new(off * sign, 1e-12).unwrap_or_else(|| self.face_normal(face));
        SurfacePoint {
            point: proj.point,
            normal,
            signed_distance: sign * d,
        }
    }

    fn ray_hit(
        &self,
        origin: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_distance: f64,
    ) -> Option<RayHit> {
        let ray = Ray::new(*origin, direction.into_inner());
        let hit = self
            .mesh
            .cast_local_ray_and_get_normal(&ray, max_distance, false)?;
        let normal = match hit.feature {
            parry3d_f64::shape::FeatureId::Face(t) => {
                // parry reports back faces with an offset id; the face's own normal is outward.
                let n = self.mesh.indices().len() as u32;
                self.face_normal(if t >= n { t - n } else { t })
            }
            _ => Unit::try_new(hit.normal, 1e-12).unwrap_or(Vector3::z_axis()),
        };
        Some(RayHit {
            distance: hit.time_of_impact,
            point: ray.point_at(hit.time_of_impact),
            normal,
        })
    }

    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn centre(&self) -> Point3<f64> {
        self.radial.centre()
    }

    fn radius_along(&self, d: &Vector3<f64>) -> f64 {
        self.radial.radius_along(d)
    }

    /// The coil's clearance, exact: the least of parry's GJK distances between the cylinder
    /// and the triangles (only those that can be nearest: see the `clearance` module; for
    /// measuring and planning, not for the loop, which asks
    /// [`MeshHead::coil_clearance_sampled`]); cutting in, as deep as its deepest face or rim
    /// point.
    fn coil_clearance(&self, head_from_coil: &Isometry3<f64>, coil: &CoilSolid) -> f64 {
        let (deepest, nearest) = coil
            .key_points(head_from_coil)
            .map(|p| (self.distance_below(&p, 0.0), p))
            .fold((f64::INFINITY, Point3::origin()), |a, b| {
                if b.0 < a.0 { b } else { a }
            });
        if deepest <= 0.0 {
            return deepest;
        }
        // The nearest sample's own distance: no nearer than the coil, so a bound to beat.
        let at_most = self.signed_distance(&nearest);
        crate::clearance::least_distance(&self.mesh, coil, head_from_coil, at_most)
            .unwrap_or_else(|| self.coil_clearance_by_parry(head_from_coil, coil))
    }
}

impl MeshHead {
    /// The coil's clearance by parry's own cylinder-against-mesh query (outside the head):
    /// what [`HeadShape::coil_clearance`] is measured against.
    pub fn coil_clearance_by_parry(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
    ) -> f64 {
        let convex = coil.convex();
        parry3d_f64::query::distance(
            &convex.placed(head_from_coil),
            convex.shape(),
            &Isometry3::identity(),
            &self.mesh,
        )
        // The pair is one parry's dispatcher handles; were it not, touching, never clear.
        .unwrap_or(0.0)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::ellipsoid::Ellipsoid;

    /// A regular octahedron of "radius" `r`, wound outward.
    pub(crate) fn octahedron(r: f64) -> Mesh {
        let vertices = vec![
            Point3::new(r, 0.0, 0.0),
            Point3::new(-r, 0.0, 0.0),
            Point3::new(0.0, r, 0.0),
            Point3::new(0.0, -r, 0.0),
            Point3::new(0.0, 0.0, r),
            Point3::new(0.0, 0.0, -r),
        ];
        let triangles = vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        Mesh {
            vertices,
            triangles,
        }
    }

    /// An ellipsoid as a fine mesh: the octahedron subdivided `n` times, pushed onto it.
    pub(crate) fn ellipsoid_mesh(radii: &Vector3<f64>, n: usize) -> Mesh {
        let mut m = octahedron(1.0);
        for _ in 0..n {
            m = m.subdivided();
        }
        for v in &mut m.vertices {
            v.coords = v.coords.normalize().component_mul(radii);
        }
        m
    }

    /// A field's grid kept and given back builds the same field, and one that is not this
    /// mesh's (another box, a triangle it lacks, a value beyond the band) is built anew.
    #[test]
    fn a_kept_field_grid_is_taken_only_for_its_own_mesh() {
        let radii = Vector3::new(0.075, 0.095, 0.11);
        let mesh = ellipsoid_mesh(&radii, 4);
        let fresh = MeshHead::new(mesh.clone(), "e").unwrap();
        let grid = fresh.field_grid();
        let (kept, taken) = MeshHead::with_field_grid(mesh.clone(), "e", grid.clone()).unwrap();
        assert!(taken);
        for p in [[0.0, 0.0, 0.12], [0.05, 0.02, -0.03], [0.0, 0.0, 0.0]] {
            let p = Point3::from(p);
            assert_eq!(fresh.signed_distance(&p), kept.signed_distance(&p));
            assert_eq!(fresh.field_value(&p), kept.field_value(&p));
        }
        let moved = mesh
            .clone()
            .transformed(&Isometry3::translation(0.001, 0.0, 0.0));
        let mut no_triangle = grid.clone();
        no_triangle.nearest[7] = mesh.triangles.len() as u32;
        let mut beyond = grid.clone();
        beyond.values[3] = 0.5;
        let mut short = grid.clone();
        short.values.pop();
        for (m, g) in [
            (moved, grid),
            (mesh.clone(), no_triangle),
            (mesh.clone(), beyond),
            (mesh, short),
        ] {
            let (head, taken) = MeshHead::with_field_grid(m.clone(), "e", g).unwrap();
            assert!(!taken);
            assert_eq!(
                head.field_grid(),
                MeshHead::new(m, "e").unwrap().field_grid()
            );
        }
    }

    /// The mesh of an ellipsoid answers as the ellipsoid does, within the mesh's own
    /// approximation (its chords cut at most a fraction of a millimetre inside).
    #[test]
    fn a_decimated_mesh_is_smaller_and_stays_on_the_shape() {
        let radii = Vector3::new(0.075, 0.095, 0.11);
        let fine = ellipsoid_mesh(&radii, 5);
        let coarse = fine.decimated(1500);
        assert!(coarse.triangles.len() <= 1500 && coarse.triangles.len() > 300);
        let e = Ellipsoid::new(Isometry3::identity(), radii).unwrap();
        for p in &coarse.vertices {
            // Cluster means lie just inside the surface they came from.
            let d = e.signed_distance(p);
            assert!(d < 1e-9 && d > -0.004, "{p}: {d}");
        }
        for t in &coarse.triangles {
            assert!(t.iter().all(|&v| (v as usize) < coarse.vertices.len()));
        }
    }

    #[test]
    fn a_fine_mesh_of_an_ellipsoid_agrees_with_the_ellipsoid() {
        let radii = Vector3::new(0.075, 0.095, 0.11);
        let e = Ellipsoid::new(Isometry3::identity(), radii).unwrap();
        let m = MeshHead::new(ellipsoid_mesh(&radii, 6), "e").unwrap();
        assert_eq!(m.triangles().len(), 8 * 4usize.pow(6));
        let mut rng = mocomp_testkit::SplitMix64(3);
        let mut next = || rng.next_f64() - 0.5;
        let coil = CoilSolid::new(0.04, 0.03).unwrap();
        for _ in 0..500 {
            let p = Point3::new(0.4 * next(), 0.4 * next(), 0.4 * next());
            let (de, dm) = (e.signed_distance(&p), m.signed_distance(&p));
            let n = e.nearest(&p);
            // Chords lie inside the ellipsoid by at most ~0.1 mm at this resolution.
            assert!((n.signed_distance - dm).abs() < 3e-4, "{p} {de} {dm}");
            let nm = m.nearest(&p);
            assert!(nm.normal.dot(&n.normal) > 0.95, "{p}");
            let pose = Isometry3::new(
                p.coords,
                Vector3::new(3.0 * next(), 3.0 * next(), 3.0 * next()),
            );
            let (ce, cm) = (
                e.coil_clearance(&pose, &coil),
                m.coil_clearance(&pose, &coil),
            );
            if ce.abs() < 0.04 {
                // Near: the same, to the chords and the tolerance.
                assert!((ce - cm).abs() < 3e-4, "{pose} {ce} {cm}");
            } else if ce < 0.0 {
                // Cutting in: as deep as its deepest point or deeper (the ellipsoid's figure is
                // the deepest of 18 sampled points).
                assert!(cm <= ce + 3e-4, "{pose} {ce} {cm}");
            } else {
                assert!(cm <= ce + 3e-4 && cm > 0.0, "{pose} {ce} {cm}");
            }
            let dir = Unit::new_normalize(-p.coords);
            let (he, hm) = (e.ray_hit(&p, &dir, 1.0), m.ray_hit(&p, &dir, 1.0));
            assert_eq!(he.is_some(), hm.is_some());
            if let (Some(a), Some(b)) = (he, hm) {
                assert!((a.distance - b.distance).abs() < 3e-4);
                assert!(a.normal.dot(&b.normal) > 0.95);
            }
        }
        // A coil wholly inside the head is not clear of it.
        let inside = Isometry3::translation(0.0, 0.0, 0.02);
        assert!(m.coil_clearance(&inside, &coil) < -0.01);
    }
}
