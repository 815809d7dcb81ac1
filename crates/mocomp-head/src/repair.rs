//! A mesh as files have it made into a surface with an inside: welded, cleaned, consistently
//! wound, turned outward, holes closed, inner shells dropped. Every change is counted, so the
//! caller can say what it did; what cannot be mended is a named error.

use crate::error::HeadError;
use crate::mesh::Mesh;
use mocomp_geom::nalgebra::{Point3, Vector3};
use serde::Serialize;
use std::collections::HashMap;
use std::collections::hash_map::Entry;

/// What [`repair`] found and did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Repairs {
    /// Vertices at the same position merged into one (a triangle soup, as STL is, has every
    /// vertex once per triangle).
    pub merged_vertices: usize,
    /// Triangles with no area (a repeated vertex, or collinear) removed.
    pub degenerate_triangles: usize,
    /// Triangles repeated (the same three vertices) removed.
    pub duplicate_triangles: usize,
    /// Triangles turned to wind the same way as their neighbours.
    pub flipped_triangles: usize,
    /// Whether the whole surface was wound inward and was turned outward.
    pub turned_outward: bool,
    /// Holes (loops of edges with a triangle on one side only) closed.
    pub holes_closed: usize,
    /// Edges on those loops.
    pub hole_edges: usize,
    /// Separate pieces dropped because they lie inside the outer one or are smaller (inner
    /// structures, debris): the head is its outer shell.
    pub pieces_dropped: usize,
    /// Vertices no triangle uses, removed.
    pub unused_vertices: usize,
    /// Whether the surface was closed as read (no hole, before any change).
    pub closed_as_read: bool,
}

impl Repairs {
    /// The changes as short phrases, for a report (empty when nothing was changed).
    pub fn phrases(&self) -> Vec<String> {
        let mut v = Vec::new();
        let mut say = |n: usize, what: &str| {
            if n > 0 {
                v.push(format!("{n} {what}"));
            }
        };
        say(self.merged_vertices, "duplicate vertices merged");
        say(self.degenerate_triangles, "degenerate triangles removed");
        say(self.duplicate_triangles, "duplicate triangles removed");
        say(
            self.flipped_triangles,
            "triangles turned to agree with their neighbours",
        );
        say(self.holes_closed, "holes closed");
        say(self.pieces_dropped, "inner or separate pieces dropped");
        say(self.unused_vertices, "unused vertices removed");
        if self.turned_outward {
            v.push("normals pointed inward: the surface was turned outward".into());
        }
        v
    }
}

/// Mends `mesh` (read from `file`) into one closed, consistently and outwardly wound surface.
/// Errors: a non-finite vertex, an index out of range, nothing left, an edge shared by more than
/// two triangles, a surface that cannot be wound consistently (one-sided, as a Möbius strip).
pub fn repair(mesh: Mesh, file: &str) -> Result<(Mesh, Repairs), HeadError> {
    let mut r = Repairs::default();
    check_numbers(&mesh, file)?;
    let Mesh {
        vertices,
        triangles,
    } = mesh;
    let (vertices, triangles) = weld(vertices, triangles, &mut r);
    let mut triangles = clean(&vertices, triangles, &mut r);
    if triangles.is_empty() {
        return Err(HeadError::Empty {
            file: file.into(),
            what: "no triangle with an area is left".into(),
        });
    }
    let edges = EdgeMap::new(&triangles);
    if let Some((a, b)) = edges.non_manifold() {
        return Err(HeadError::Shape {
            file: file.into(),
            what: format!(
                "the edge between vertices {a} and {b} is shared by more than two triangles: not a surface with an inside"
            ),
        });
    }
    let pieces = orient(&mut triangles, &edges, file, &mut r)?;
    r.closed_as_read = edges.boundary_count() == 0;
    let mut vertices = vertices;
    close_holes(&mut vertices, &mut triangles, &mut r);
    let triangles = outer_shell(&vertices, triangles, &pieces, &mut r);
    let mesh = compact(vertices, triangles, &mut r);
    Ok((mesh, r))
}

fn check_numbers(mesh: &Mesh, file: &str) -> Result<(), HeadError> {
    if mesh.triangles.is_empty() {
        return Err(HeadError::Empty {
            file: file.into(),
            what: "no triangles".into(),
        });
    }
    if let Some((i, v)) = mesh
        .vertices
        .iter()
        .enumerate()
        .find(|(_, v)| !v.iter().all(|c| c.is_finite()))
    {
        return Err(HeadError::NotFinite {
            file: file.into(),
            vertex: i,
            coords: [v.x, v.y, v.z],
        });
    }
    let n = mesh.vertices.len();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if let Some(&bad) = tri.iter().find(|&&i| i as usize >= n) {
            return Err(HeadError::BadIndex {
                file: file.into(),
                triangle: t,
                index: i64::from(bad),
                vertices: n,
            });
        }
    }
    Ok(())
}

/// Merges vertices at exactly the same position (`-0.0` and `0.0` alike).
fn weld(
    vertices: Vec<Point3<f64>>,
    triangles: Vec<[u32; 3]>,
    r: &mut Repairs,
) -> (Vec<Point3<f64>>, Vec<[u32; 3]>) {
    let key = |p: &Point3<f64>| p.coords.map(|c| (c + 0.0).to_bits());
    let mut first: HashMap<Vector3<u64>, u32> = HashMap::with_capacity(vertices.len());
    let mut kept = Vec::with_capacity(vertices.len());
    let mut remap = Vec::with_capacity(vertices.len());
    for v in &vertices {
        let next = kept.len() as u32;
        match first.entry(key(v)) {
            Entry::Occupied(e) => remap.push(*e.get()),
            Entry::Vacant(e) => {
                e.insert(next);
                kept.push(*v);
                remap.push(next);
            }
        }
    }
    r.merged_vertices = vertices.len() - kept.len();
    let triangles = triangles
        .into_iter()
        .map(|t| t.map(|i| remap[i as usize]))
        .collect();
    (kept, triangles)
}

/// Removes triangles without area and repeated triangles.
fn clean(vertices: &[Point3<f64>], triangles: Vec<[u32; 3]>, r: &mut Repairs) -> Vec<[u32; 3]> {
    let extent = crate::shape::Aabb::around(vertices).map_or(1.0, |b| b.extent());
    // Twice the area below which a triangle has no usable normal: (1e-7 of the head's size)².
    let tiny = (1e-7 * extent).powi(2);
    let mut seen = std::collections::HashSet::with_capacity(triangles.len());
    let mut out = Vec::with_capacity(triangles.len());
    for t in triangles {
        let [a, b, c] = t.map(|i| vertices[i as usize]);
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || (b - a).cross(&(c - a)).norm() <= tiny {
            r.degenerate_triangles += 1;
            continue;
        }
        let mut k = t;
        k.sort_unstable();
        if !seen.insert(k) {
            r.duplicate_triangles += 1;
            continue;
        }
        out.push(t);
    }
    out
}

/// The triangles on each undirected edge.
struct EdgeMap {
    edges: HashMap<(u32, u32), Vec<u32>>,
}

impl EdgeMap {
    fn new(triangles: &[[u32; 3]]) -> Self {
        let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::with_capacity(triangles.len() * 2);
        for (i, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                edges
                    .entry((a.min(b), a.max(b)))
                    .or_default()
                    .push(i as u32);
            }
        }
        Self { edges }
    }

    fn non_manifold(&self) -> Option<(u32, u32)> {
        self.edges
            .iter()
            .filter(|(_, t)| t.len() > 2)
            .map(|(e, _)| *e)
            .min()
    }

    fn boundary_count(&self) -> usize {
        self.edges.values().filter(|t| t.len() == 1).count()
    }

    /// The other triangle on edge (a, b) of triangle `t`, if any.
    fn across(&self, a: u32, b: u32, t: u32) -> Option<u32> {
        self.edges
            .get(&(a.min(b), a.max(b)))?
            .iter()
            .copied()
            .find(|&o| o != t)
    }
}

/// Whether triangle `t` runs from `a` to `b` along one of its edges.
fn runs(t: &[u32; 3], a: u32, b: u32) -> bool {
    (0..3).any(|k| t[k] == a && t[(k + 1) % 3] == b)
}

/// Winds every piece (connected by edges) the way its first triangle is wound; returns each
/// triangle's piece.
fn orient(
    triangles: &mut [[u32; 3]],
    edges: &EdgeMap,
    file: &str,
    r: &mut Repairs,
) -> Result<Vec<u32>, HeadError> {
    const NONE: u32 = u32::MAX;
    let mut piece = vec![NONE; triangles.len()];
    let mut stack = Vec::new();
    let mut pieces = 0u32;
    for seed in 0..triangles.len() {
        if piece[seed] != NONE {
            continue;
        }
        piece[seed] = pieces;
        stack.push(seed as u32);
        while let Some(t) = stack.pop() {
            let tri = triangles[t as usize];
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let Some(o) = edges.across(a, b, t) else {
                    continue;
                };
                // A neighbour wound the same way runs the shared edge the other way: b → a.
                let agrees = !runs(&triangles[o as usize], a, b);
                if piece[o as usize] == NONE {
                    piece[o as usize] = pieces;
                    if !agrees {
                        triangles[o as usize].swap(1, 2);
                        r.flipped_triangles += 1;
                    }
                    stack.push(o);
                } else if !agrees {
                    return Err(HeadError::Shape {
                        file: file.into(),
                        what: format!(
                            "triangles {t} and {o} cannot be wound the same way: the surface is one-sided"
                        ),
                    });
                }
            }
        }
        pieces += 1;
    }
    Ok(piece)
}

/// Closes each loop of boundary edges with a fan about its centroid (a new vertex), wound to
/// agree with the triangles along it.
fn close_holes(vertices: &mut Vec<Point3<f64>>, triangles: &mut Vec<[u32; 3]>, r: &mut Repairs) {
    let edges = EdgeMap::new(triangles);
    // Each boundary edge as its triangle runs it; the fan runs it back.
    let mut next: HashMap<u32, u32> = HashMap::new();
    for ((a, b), ts) in &edges.edges {
        if let [t] = ts.as_slice() {
            let (from, to) = if runs(&triangles[*t as usize], *a, *b) {
                (*a, *b)
            } else {
                (*b, *a)
            };
            next.insert(from, to);
        }
    }
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    for start in starts {
        if !next.contains_key(&start) {
            continue;
        }
        let mut lp = vec![start];
        let mut at = start;
        while let Some(to) = next.remove(&at) {
            if to == start {
                break;
            }
            lp.push(to);
            at = to;
        }
        if lp.len() < 3 {
            continue;
        }
        let c = lp
            .iter()
            .fold(Vector3::zeros(), |s, &i| s + vertices[i as usize].coords)
            / lp.len() as f64;
        let ci = vertices.len() as u32;
        vertices.push(Point3::from(c));
        for k in 0..lp.len() {
            let (a, b) = (lp[k], lp[(k + 1) % lp.len()]);
            triangles.push([b, a, ci]);
        }
        r.holes_closed += 1;
        r.hole_edges += lp.len();
    }
}

/// Signed volume of a closed piece (positive when wound outward).
fn volume(vertices: &[Point3<f64>], tris: impl Iterator<Item = [u32; 3]>) -> f64 {
    tris.map(|t| {
        let [a, b, c] = t.map(|i| vertices[i as usize].coords);
        a.dot(&b.cross(&c))
    })
    .sum::<f64>()
        / 6.0
}

/// Keeps the piece with the largest volume (the outer shell), wound outward.
fn outer_shell(
    vertices: &[Point3<f64>],
    triangles: Vec<[u32; 3]>,
    pieces: &[u32],
    r: &mut Repairs,
) -> Vec<[u32; 3]> {
    // The fans added by close_holes join the piece of the triangle they border; a fan triangle's
    // piece is found through its first two vertices' edge.
    let edges = EdgeMap::new(&triangles);
    let n_orig = pieces.len();
    let piece_of = |t: usize| -> u32 {
        if t < n_orig {
            return pieces[t];
        }
        let tri = triangles[t];
        edges.across(tri[0], tri[1], t as u32).map_or(0, |o| {
            if (o as usize) < n_orig {
                pieces[o as usize]
            } else {
                0
            }
        })
    };
    let count = pieces.iter().copied().max().map_or(0, |m| m as usize + 1);
    let mut vol = vec![0.0; count];
    for t in 0..triangles.len() {
        vol[piece_of(t) as usize] += volume(vertices, std::iter::once(triangles[t]));
    }
    let keep = (0..count)
        .max_by(|&a, &b| vol[a].abs().total_cmp(&vol[b].abs()))
        .unwrap_or(0);
    r.pieces_dropped = count.saturating_sub(1);
    r.turned_outward = vol[keep] < 0.0;
    let flip = r.turned_outward;
    (0..triangles.len())
        .filter(|&t| piece_of(t) as usize == keep)
        .map(|t| {
            let [a, b, c] = triangles[t];
            if flip { [a, c, b] } else { [a, b, c] }
        })
        .collect()
}

/// Drops the vertices no triangle uses, keeping the others' order.
fn compact(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>, r: &mut Repairs) -> Mesh {
    let mut new_index = vec![u32::MAX; vertices.len()];
    for t in &triangles {
        for &i in t {
            new_index[i as usize] = 0;
        }
    }
    let mut kept = Vec::with_capacity(vertices.len());
    for (i, v) in vertices.iter().enumerate() {
        if new_index[i] == 0 {
            new_index[i] = kept.len() as u32;
            kept.push(*v);
        }
    }
    r.unused_vertices = vertices.len() - kept.len();
    Mesh {
        vertices: kept,
        triangles: triangles
            .into_iter()
            .map(|t| t.map(|i| new_index[i as usize]))
            .collect(),
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::mesh::tests::octahedron;

    #[test]
    fn a_clean_closed_mesh_is_left_as_it_is() {
        let m = octahedron(0.1);
        let (out, r) = repair(m.clone(), "o").unwrap();
        assert_eq!(out, m);
        assert_eq!(r.phrases(), Vec::<String>::new());
        assert!(r.closed_as_read);
    }

    #[test]
    fn a_soup_is_welded_and_a_flipped_triangle_turned_back() {
        let m = octahedron(0.1);
        // As STL has it: three vertices per triangle, one triangle wound the wrong way.
        let mut soup = Mesh {
            vertices: Vec::new(),
            triangles: Vec::new(),
        };
        for (k, t) in m.triangles.iter().enumerate() {
            let base = soup.vertices.len() as u32;
            soup.vertices
                .extend(t.iter().map(|&i| m.vertices[i as usize]));
            soup.triangles.push(if k == 3 {
                [base, base + 2, base + 1]
            } else {
                [base, base + 1, base + 2]
            });
        }
        let (out, r) = repair(soup, "soup").unwrap();
        assert_eq!(out.vertices.len(), 6);
        assert_eq!(r.merged_vertices, 24 - 6);
        assert_eq!(r.flipped_triangles, 1);
        assert!(!r.turned_outward);
        assert!(volume(&out.vertices, out.triangles.iter().copied()) > 0.0);
    }

    #[test]
    fn an_inside_out_mesh_with_a_hole_and_junk_is_mended() {
        let mut m = octahedron(0.1);
        for t in &mut m.triangles {
            t.swap(1, 2);
        }
        let hole = m.triangles.remove(0);
        m.triangles.push(m.triangles[0]);
        m.triangles.push([hole[0], hole[0], hole[1]]);
        // A small separate piece (debris) far away.
        let far = octahedron(0.01);
        let base = m.vertices.len() as u32;
        m.vertices
            .extend(far.vertices.iter().map(|p| p + Vector3::new(1.0, 0.0, 0.0)));
        m.triangles
            .extend(far.triangles.iter().map(|t| t.map(|i| i + base)));
        m.vertices.push(Point3::new(5.0, 5.0, 5.0));
        let (out, r) = repair(m, "bad").unwrap();
        assert!(!r.closed_as_read);
        assert_eq!((r.holes_closed, r.hole_edges), (1, 3));
        assert_eq!(r.duplicate_triangles, 1);
        assert_eq!(r.degenerate_triangles, 1);
        assert_eq!(r.pieces_dropped, 1);
        assert!(r.turned_outward);
        assert_eq!(r.unused_vertices, 7);
        // 7 octahedron faces and a 3-triangle fan about the hole's centre.
        assert_eq!((out.vertices.len(), out.triangles.len()), (7, 10));
        assert!(volume(&out.vertices, out.triangles.iter().copied()) > 0.0);
        assert!(EdgeMap::new(&out.triangles).boundary_count() == 0);
    }

    #[test]
    fn what_cannot_be_mended_is_named() {
        let mut m = octahedron(0.1);
        m.vertices[2].y = f64::NAN;
        let e = repair(m, "nan.stl").unwrap_err().to_string();
        assert!(e.contains("nan.stl: vertex 2 is not finite"), "{e}");
        let mut m = octahedron(0.1);
        m.triangles[5][1] = 99;
        let e = repair(m, "i.obj").unwrap_err().to_string();
        assert!(
            e.contains("triangle 5 uses vertex 99, but there are 6"),
            "{e}"
        );
        let mut m = octahedron(0.1);
        let t = m.triangles[0];
        m.vertices.push(Point3::new(0.0, 0.0, 0.3));
        m.triangles.push([t[0], t[1], 6]);
        let e = repair(m, "fin.ply").unwrap_err().to_string();
        assert!(e.contains("shared by more than two triangles"), "{e}");
        let m = Mesh {
            vertices: vec![Point3::origin(); 3],
            triangles: vec![[0, 1, 2]],
        };
        let e = repair(m, "flat.stl").unwrap_err().to_string();
        assert!(e.contains("no triangle with an area"), "{e}");
    }
}
