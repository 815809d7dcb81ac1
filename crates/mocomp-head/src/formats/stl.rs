//! STL through `stl_io`: binary when the size matches the count in its header (a binary file's
//! header may itself begin with "solid"), ASCII otherwise.

use super::{MAX_TRIANGLES, check_count};
use crate::error::HeadError;
use crate::mesh::Mesh;
use mocomp_geom::nalgebra::Point3;
use std::io::Cursor;

pub(super) fn read(file: &str, bytes: &[u8]) -> Result<Mesh, HeadError> {
    let binary = bytes.len() >= 84 && {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]);
        84 + 50 * u64::from(n) == bytes.len() as u64 || !bytes.starts_with(b"solid")
    };
    // stl_io tells ASCII from binary by a leading "solid"; a binary header is free text and may
    // begin so too: such a header is blanked in a copy first.
    let blanked;
    let bytes = if binary && bytes.starts_with(b"solid") {
        let mut copy = bytes.to_vec();
        copy[..5].copy_from_slice(b"     ");
        blanked = copy;
        &blanked[..]
    } else {
        bytes
    };
    if binary {
        let n = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]);
        check_count(
            file,
            "triangles",
            u64::from(n),
            MAX_TRIANGLES,
            Some((bytes.len() as u64 - 84, 50)),
        )?;
    } else {
        // An ASCII triangle takes at least ~90 bytes of text: the file's size bounds the count.
        check_count(
            file,
            "triangles (at most, by size)",
            bytes.len() as u64 / 90,
            MAX_TRIANGLES,
            None,
        )?;
    }
    let mut cursor = Cursor::new(bytes);
    let triangles = stl_io::create_stl_reader(&mut cursor)
        .map_err(|e| HeadError::format(file, format!("not an STL file: {e}"), None))?;
    let mut mesh = Mesh::default();
    for (i, t) in triangles.enumerate() {
        let t = t.map_err(|e| {
            HeadError::format(
                file,
                format!("triangle {i}: {e}"),
                binary.then_some(84 + 50 * i as u64),
            )
        })?;
        if i as u64 >= MAX_TRIANGLES {
            return Err(HeadError::TooLarge {
                file: file.into(),
                what: "triangles",
                count: i as u64 + 1,
                limit: MAX_TRIANGLES,
            });
        }
        let base = mesh.vertices.len() as u32;
        for v in t.vertices {
            mesh.vertices.push(Point3::new(
                f64::from(v.0[0]),
                f64::from(v.0[1]),
                f64::from(v.0[2]),
            ));
        }
        mesh.triangles.push([base, base + 1, base + 2]);
    }
    Ok(mesh)
}
