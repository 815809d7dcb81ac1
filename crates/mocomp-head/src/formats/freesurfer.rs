//! FreeSurfer's binary triangle surface (`lh.seghead`, `bem/outer_skin.surf`): the magic
//! number FF FF FE, a "created by" line ending in two newlines, big-endian vertex and face
//! counts, the vertices (float32, millimetres, surface RAS) and the faces (int32), then perhaps
//! the volume geometry, whose `cras` takes surface RAS to the scanner's.
//!
//! Written here rather than through a crate: the format is these few fields, and the one crate
//! for it allocates from the declared counts before it knows the bytes are there.

use super::{MAX_TRIANGLES, MAX_VERTICES, check_count};
use crate::error::HeadError;
use crate::mesh::Mesh;
use mocomp_geom::nalgebra::Point3;

/// The magic number that opens a triangle surface.
pub(super) const MAGIC: [u8; 3] = [0xff, 0xff, 0xfe];

fn be_u32(bytes: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_be_bytes(bytes.get(at..at + 4)?.try_into().ok()?))
}

pub(super) fn read(file: &str, bytes: &[u8]) -> Result<(Mesh, String), HeadError> {
    let text_end = bytes[3..]
        .windows(2)
        .position(|w| w == b"\n\n")
        .map(|p| p + 3 + 2)
        .ok_or_else(|| {
            HeadError::format(
                file,
                "no end to the \"created by\" line (two newlines)",
                Some(3),
            )
        })?;
    let (Some(nv), Some(nf)) = (be_u32(bytes, text_end), be_u32(bytes, text_end + 4)) else {
        return Err(HeadError::format(
            file,
            "truncated before the vertex and face counts",
            Some(text_end as u64),
        ));
    };
    let body = text_end + 8;
    let rest = (bytes.len() - body.min(bytes.len())) as u64;
    let nv = check_count(
        file,
        "vertices",
        u64::from(nv),
        MAX_VERTICES,
        Some((rest, 12)),
    )?;
    let after_vertices = rest - 12 * nv as u64;
    let nf = check_count(
        file,
        "triangles",
        u64::from(nf),
        MAX_TRIANGLES,
        Some((after_vertices, 12)),
    )?;
    let f32_at = |i: usize| {
        let at = body + 4 * i;
        f32::from_be_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
    };
    let vertices = (0..nv)
        .map(|i| {
            Point3::new(
                f64::from(f32_at(3 * i)),
                f64::from(f32_at(3 * i + 1)),
                f64::from(f32_at(3 * i + 2)),
            )
        })
        .collect();
    let faces_at = body + 12 * nv;
    let mut triangles = Vec::with_capacity(nf);
    for t in 0..nf {
        let mut tri = [0u32; 3];
        for (k, slot) in tri.iter_mut().enumerate() {
            let at = faces_at + 4 * (3 * t + k);
            let v = be_u32(bytes, at).unwrap_or(u32::MAX);
            if v as usize >= nv {
                return Err(HeadError::BadIndex {
                    file: file.into(),
                    triangle: t,
                    index: i64::from(v as i32),
                    vertices: nv,
                });
            }
            *slot = v;
        }
        triangles.push(tri);
    }
    let tail = &bytes[faces_at + 12 * nf..];
    let frame = match cras(tail) {
        Some(c) => format!(
            "FreeSurfer surface RAS (tkregister), mm; scanner RAS = surface RAS + c_ras ({:.3}, {:.3}, {:.3})",
            c[0], c[1], c[2]
        ),
        None => "FreeSurfer surface RAS (tkregister), mm; no volume geometry".to_string(),
    };
    Ok((
        Mesh {
            vertices,
            triangles,
        },
        frame,
    ))
}

/// The `cras = x y z` line of the volume geometry after the faces, if there is one.
fn cras(tail: &[u8]) -> Option<[f64; 3]> {
    let text = String::from_utf8_lossy(tail);
    let line = text.lines().find(|l| l.trim_start().starts_with("cras"))?;
    let nums: Vec<f64> = line
        .split('=')
        .nth(1)?
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    (nums.len() == 3).then(|| [nums[0], nums[1], nums[2]])
}

/// A surface in the format, as FreeSurfer writes it (for tests of this reader against the
/// bytes nibabel writes, and of its limits).
#[cfg(test)]
pub(crate) fn write(mesh: &Mesh, tail: &str) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(b"created by mocomp\n\n");
    out.extend_from_slice(&(mesh.vertices.len() as u32).to_be_bytes());
    out.extend_from_slice(&(mesh.triangles.len() as u32).to_be_bytes());
    for v in &mesh.vertices {
        for c in v.iter() {
            out.extend_from_slice(&(*c as f32).to_be_bytes());
        }
    }
    for t in &mesh.triangles {
        for i in t {
            out.extend_from_slice(&i.to_be_bytes());
        }
    }
    out.extend_from_slice(tail.as_bytes());
    out
}
