//! PLY through `ply-rs-bw` (the maintained fork; `ply-rs` is not): the header first, its counts
//! checked, then the payload. Polygons are cut into triangles as fans.

use super::{MAX_TRIANGLES, MAX_VERTICES, check_count};
use crate::error::HeadError;
use crate::mesh::Mesh;
use mocomp_geom::nalgebra::Point3;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, DefaultElement, ElementDef, Encoding, Ply, Property, PropertyDef, PropertyType,
    ScalarType,
};
use std::io::BufReader;

fn number(p: &Property) -> Option<f64> {
    Some(match *p {
        Property::Char(v) => f64::from(v),
        Property::UChar(v) => f64::from(v),
        Property::Short(v) => f64::from(v),
        Property::UShort(v) => f64::from(v),
        Property::Int(v) => f64::from(v),
        Property::UInt(v) => f64::from(v),
        Property::Float(v) => f64::from(v),
        Property::Double(v) => v,
        _ => return None,
    })
}

fn indices(p: &Property) -> Option<Vec<i64>> {
    Some(match p {
        Property::ListChar(v) => v.iter().map(|&x| i64::from(x)).collect(),
        Property::ListUChar(v) => v.iter().map(|&x| i64::from(x)).collect(),
        Property::ListShort(v) => v.iter().map(|&x| i64::from(x)).collect(),
        Property::ListUShort(v) => v.iter().map(|&x| i64::from(x)).collect(),
        Property::ListInt(v) => v.iter().map(|&x| i64::from(x)).collect(),
        Property::ListUInt(v) => v.iter().map(|&x| i64::from(x)).collect(),
        _ => return None,
    })
}

pub(super) fn read(file: &str, bytes: &[u8]) -> Result<Mesh, HeadError> {
    let parser = Parser::<DefaultElement>::new();
    let mut reader = Reader::new(BufReader::new(bytes));
    let header = parser
        .read_header(&mut reader)
        .map_err(|e| HeadError::format(file, format!("not a PLY header: {e}"), None))?;
    let count = |name: &str| header.elements.get(name).map_or(0, |e| e.count as u64);
    check_count(file, "vertices", count("vertex"), MAX_VERTICES, None)?;
    check_count(file, "faces", count("face"), MAX_TRIANGLES, None)?;
    let payload = parser
        .read_payload(&mut reader, &header)
        .map_err(|e| HeadError::format(file, format!("PLY payload: {e}"), None))?;
    let mut mesh = Mesh::default();
    for (i, v) in payload.get("vertex").into_iter().flatten().enumerate() {
        let c = |k: &str| v.get(k).and_then(number);
        let (Some(x), Some(y), Some(z)) = (c("x"), c("y"), c("z")) else {
            return Err(HeadError::format(
                file,
                format!("vertex {i} has no numeric x, y and z"),
                None,
            ));
        };
        mesh.vertices.push(Point3::new(x, y, z));
    }
    let n = mesh.vertices.len();
    for (i, f) in payload.get("face").into_iter().flatten().enumerate() {
        let list = f
            .get("vertex_indices")
            .or_else(|| f.get("vertex_index"))
            .and_then(indices)
            .ok_or_else(|| {
                HeadError::format(file, format!("face {i} has no vertex_indices list"), None)
            })?;
        if list.len() < 3 {
            return Err(HeadError::format(
                file,
                format!("face {i} has {} vertices", list.len()),
                None,
            ));
        }
        let index = |k: i64| -> Result<u32, HeadError> {
            u32::try_from(k)
                .ok()
                .filter(|&u| (u as usize) < n)
                .ok_or_else(|| HeadError::BadIndex {
                    file: file.into(),
                    triangle: i,
                    index: k,
                    vertices: n,
                })
        };
        for k in 1..list.len() - 1 {
            mesh.triangles
                .push([index(list[0])?, index(list[k])?, index(list[k + 1])?]);
        }
        if mesh.triangles.len() as u64 > MAX_TRIANGLES {
            return Err(HeadError::TooLarge {
                file: file.into(),
                what: "triangles",
                count: mesh.triangles.len() as u64,
                limit: MAX_TRIANGLES,
            });
        }
    }
    Ok(mesh)
}

/// `mesh` as a binary little-endian PLY in `unit_scale` units per metre (1000 for
/// millimetres), vertices as doubles (nothing lost), faces as lists of ints.
pub fn write_ply(mesh: &Mesh, unit_scale: f64) -> Result<Vec<u8>, HeadError> {
    let mut ply = Ply::<DefaultElement>::new();
    ply.header.encoding = Encoding::BinaryLittleEndian;
    let mut vertex = ElementDef::new("vertex".into());
    for k in ["x", "y", "z"] {
        vertex.properties.add(PropertyDef::new(
            k.into(),
            PropertyType::Scalar(ScalarType::Double),
        ));
    }
    ply.header.elements.add(vertex);
    let mut face = ElementDef::new("face".into());
    face.properties.add(PropertyDef::new(
        "vertex_indices".into(),
        PropertyType::List(ScalarType::UChar, ScalarType::Int),
    ));
    ply.header.elements.add(face);
    let vertices = mesh
        .vertices
        .iter()
        .map(|p| {
            let mut e = DefaultElement::new();
            for (k, c) in ["x", "y", "z"].into_iter().zip(p.iter()) {
                e.insert(k.into(), Property::Double(c * unit_scale));
            }
            e
        })
        .collect();
    ply.payload.insert("vertex".into(), vertices);
    let faces = mesh
        .triangles
        .iter()
        .map(|t| {
            let mut e = DefaultElement::new();
            // Indices come from a mesh of at most MAX_VERTICES (< i32::MAX) vertices.
            e.insert(
                "vertex_indices".into(),
                Property::ListInt(t.iter().map(|&i| i as i32).collect()),
            );
            e
        })
        .collect();
    ply.payload.insert("face".into(), faces);
    let mut out = Vec::new();
    ply_rs_bw::writer::Writer::new()
        .write_ply(&mut out, &mut ply)
        .map_err(|e| HeadError::format("PLY output", e.to_string(), None))?;
    Ok(out)
}
