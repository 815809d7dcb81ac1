//! Wavefront OBJ through `tobj`, every object's triangles into one mesh (faces with more sides
//! triangulated; materials ignored: a head has none worth reading).

use super::{MAX_TRIANGLES, MAX_VERTICES, check_count};
use crate::error::HeadError;
use crate::mesh::Mesh;
use mocomp_geom::nalgebra::Point3;

pub(super) fn read(file: &str, bytes: &[u8]) -> Result<Mesh, HeadError> {
    // The counts, from the lines that declare them, before tobj allocates anything.
    let (mut v, mut f) = (0u64, 0u64);
    for line in bytes.split(|&b| b == b'\n') {
        match line {
            [b'v', b' ' | b'\t', ..] => v += 1,
            [b'f', b' ' | b'\t', ..] => f += 1,
            _ => {}
        }
    }
    check_count(file, "vertices", v, MAX_VERTICES, None)?;
    check_count(file, "faces", f, MAX_TRIANGLES, None)?;
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj_buf(&mut &bytes[..], &options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| HeadError::format(file, format!("not an OBJ file: {e}"), None))?;
    let mut mesh = Mesh::default();
    for m in models {
        let base = mesh.vertices.len() as u32;
        mesh.vertices.extend(
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|p| Point3::new(p[0], p[1], p[2])),
        );
        mesh.triangles.extend(
            m.mesh
                .indices
                .chunks_exact(3)
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
    }
    Ok(mesh)
}
