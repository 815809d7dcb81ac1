//! Scalps' distance fields, kept (see [`crate::files::cache`]) so that each command on the same
//! head does not sweep its grid again (most of a 100 k-triangle head's start-up): the grid's
//! nodes, their triangles and values, under a key made of the mesh as the head model holds it
//! (its vertices in the head frame, its triangles) and [`mocomp_head::field::FIELD_REVISION`]
//! with the grid's constants. What is read back is checked against the mesh by
//! [`mocomp_head::MeshHead::with_field_grid`], which builds the field anew when it does not fit.

use crate::files::cache::{Kind, Reader, Refused, refused};
use mocomp_head::Mesh;
use mocomp_head::field::{EXACT_BAND_M, FIELD_REVISION, FieldGrid, MARGIN_M, SPACING_M};
use sha2::{Digest, Sha256};
use std::path::Path;

/// The most nodes a kept grid may claim (a head's is about 1.2 million).
const MAX_NODES: u64 = 50_000_000;

/// Kept fields: about 10 MB each.
pub const KIND: Kind = Kind {
    folder: "fields",
    ext: "field",
    magic: b"mocomp field  1\n",
    keep: 8,
    max_bytes: 56 + MAX_NODES * 8 + crate::files::cache::HEADER as u64 + 32,
};

/// The key for the field of `mesh` (as the head model holds it).
pub fn key(mesh: &Mesh) -> [u8; 32] {
    let mut h = Sha256::new();
    h.update(KIND.magic);
    h.update(FIELD_REVISION.to_le_bytes());
    for c in [SPACING_M, MARGIN_M, EXACT_BAND_M] {
        h.update(c.to_bits().to_le_bytes());
    }
    h.update((mesh.vertices.len() as u64).to_le_bytes());
    for v in &mesh.vertices {
        for c in [v.x, v.y, v.z] {
            h.update(c.to_bits().to_le_bytes());
        }
    }
    h.update((mesh.triangles.len() as u64).to_le_bytes());
    for t in &mesh.triangles {
        for i in t {
            h.update(i.to_le_bytes());
        }
    }
    h.finalize().into()
}

/// The grid kept under `key` under the cache's `root`, if one is there whole.
pub fn load(root: &Path, key: &[u8; 32]) -> Option<FieldGrid> {
    decode(&crate::files::cache::load(&KIND, root, key)?).ok()
}

/// Keeps `grid` under `key` under the cache's `root`.
pub fn store(root: &Path, key: &[u8; 32], grid: &FieldGrid) -> Result<(), crate::AppError> {
    crate::files::cache::store(&KIND, root, key, &encode(grid))
}

/// The content `grid` is kept as: dims (3 u64), origin (3 f64), the Lipschitz bound (f64, may be
/// infinite), then each node's triangle (u32) and each node's value (f32).
pub fn encode(grid: &FieldGrid) -> Vec<u8> {
    let n = grid.nearest.len();
    let mut out = Vec::with_capacity(56 + n * 8);
    for d in grid.dims {
        out.extend_from_slice(&(d as u64).to_le_bytes());
    }
    for c in grid.origin {
        out.extend_from_slice(&c.to_le_bytes());
    }
    out.extend_from_slice(&grid.lipschitz.to_le_bytes());
    for t in &grid.nearest {
        out.extend_from_slice(&t.to_le_bytes());
    }
    for v in &grid.values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// The grid in `content` (an envelope's), refused by the offset of what is wrong. Whether it
/// is the grid of a given mesh is [`mocomp_head::MeshHead::with_field_grid`]'s to say.
pub fn decode(content: &[u8]) -> Result<FieldGrid, Refused> {
    let mut r = Reader::new(content);
    let dims_at = r.offset();
    let dims = [r.u64()?, r.u64()?, r.u64()?];
    let nodes = dims
        .iter()
        .try_fold(1u64, |n, &d| n.checked_mul(d))
        .filter(|&n| n > 0 && n <= MAX_NODES)
        .ok_or_else(|| refused(dims_at, format!("a grid of {dims:?} nodes")))?;
    let origin = [
        r.f64("the origin")?,
        r.f64("the origin")?,
        r.f64("the origin")?,
    ];
    let lipschitz = f64::from_le_bytes(
        r.take(8)?
            .try_into()
            .map_err(|_| refused(r.offset(), "no Lipschitz bound"))?,
    );
    // At most fifty million nodes: the product fits.
    if r.left() as u64 != nodes * 8 {
        return Err(refused(
            dims_at,
            format!(
                "{nodes} nodes make {} bytes, the content has {}",
                nodes * 8,
                r.left()
            ),
        ));
    }
    let n = nodes as usize;
    let nearest = r
        .take(n * 4)?
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let values = r
        .take(n * 4)?
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok(FieldGrid {
        origin,
        dims: dims.map(|d| d as usize),
        nearest,
        values,
        lipschitz,
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::files::cache::HEADER;
    use mocomp_geom::nalgebra::Point3;

    fn grid() -> FieldGrid {
        FieldGrid {
            origin: [-0.1, -0.2, 0.3],
            dims: [2, 3, 2],
            nearest: (0..12).collect(),
            values: (0..12).map(|i| i as f32 * 0.001).collect(),
            lipschitz: f64::INFINITY,
        }
    }

    #[test]
    fn a_kept_grid_reads_back_bit_for_bit() {
        let g = grid();
        assert_eq!(decode(&encode(&g)).unwrap(), g);
    }

    #[test]
    fn forged_dimensions_and_cut_content_are_refused() {
        let good = encode(&grid());
        for dims in [
            [0u64, 3, 2],
            [u64::MAX, 2, 2],
            [1 << 30, 1 << 30, 1],
            [2, 3, 3],
        ] {
            let mut bad = good.clone();
            for (k, d) in dims.iter().enumerate() {
                bad[8 * k..8 * k + 8].copy_from_slice(&d.to_le_bytes());
            }
            assert_eq!(decode(&bad).unwrap_err().offset, HEADER, "{dims:?}");
        }
        for n in 0..good.len() {
            assert!(decode(&good[..n]).is_err(), "{n} bytes");
        }
        let mut bad = good;
        bad[24..32].copy_from_slice(&f64::NAN.to_le_bytes());
        assert!(decode(&bad).unwrap_err().what.contains("origin"));
    }

    #[test]
    fn the_key_changes_with_any_vertex_or_triangle() {
        let mesh = Mesh {
            vertices: vec![
                Point3::new(0.0, 0.0, 0.0),
                Point3::new(0.1, 0.0, 0.0),
                Point3::new(0.0, 0.1, 0.0),
            ],
            triangles: vec![[0, 1, 2]],
        };
        let base = key(&mesh);
        let mut moved = mesh.clone();
        moved.vertices[1].x += 1e-12;
        let mut turned = mesh.clone();
        turned.triangles[0] = [0, 2, 1];
        assert_ne!(key(&moved), base);
        assert_ne!(key(&turned), base);
        assert_eq!(key(&mesh.clone()), base);
    }
}
