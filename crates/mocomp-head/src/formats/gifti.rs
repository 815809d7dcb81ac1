//! GIfTI surfaces (`.gii`), as nibabel, FreeSurfer and Connectome Workbench write them: an XML
//! document whose `DataArray`s hold the points (`NIFTI_INTENT_POINTSET`, millimetres by the
//! standard) and the triangles (`NIFTI_INTENT_TRIANGLE`), each ASCII, base64 or zlib-compressed
//! base64, either byte order, row- or column-major.
//!
//! Written on `quick-xml`, `base64` and `flate2`: no crate reads GIfTI. Every array's size is
//! checked against the limits before it is decoded, and decompression stops at the size the
//! array declares (a small file cannot inflate into a large one).

use super::{MAX_TRIANGLES, MAX_VERTICES, check_count};
use crate::error::HeadError;
use crate::mesh::Mesh;
use base64::Engine;
use mocomp_geom::nalgebra::Point3;
use quick_xml::events::{BytesStart, Event};
use std::collections::HashMap;
use std::io::Read;

/// One `DataArray`: its attributes, its data's text and its coordinate system.
#[derive(Default)]
struct Array {
    attrs: HashMap<String, String>,
    data: String,
    data_space: Option<String>,
    transformed_space: Option<String>,
    offset: u64,
}

fn attributes(e: &BytesStart<'_>) -> HashMap<String, String> {
    e.attributes()
        .filter_map(Result::ok)
        .map(|a| (a.key.as_ref().to_string(), a.value.into_owned()))
        .collect()
}

pub(super) fn read(file: &str, bytes: &[u8]) -> Result<(Mesh, String), HeadError> {
    let arrays = arrays(file, bytes)?;
    let intent = |name: &str| {
        arrays
            .iter()
            .find(|a| a.attrs.get("Intent").map(String::as_str) == Some(name))
    };
    let points = intent("NIFTI_INTENT_POINTSET").ok_or_else(|| {
        HeadError::format(file, "no DataArray with Intent NIFTI_INTENT_POINTSET", None)
    })?;
    let tris = intent("NIFTI_INTENT_TRIANGLE").ok_or_else(|| {
        HeadError::format(file, "no DataArray with Intent NIFTI_INTENT_TRIANGLE", None)
    })?;
    let p = values(file, points, MAX_VERTICES, "vertices")?;
    let t = values(file, tris, MAX_TRIANGLES, "triangles")?;
    let vertices = p
        .chunks_exact(3)
        .map(|c| Point3::new(c[0], c[1], c[2]))
        .collect::<Vec<_>>();
    let n = vertices.len();
    let mut triangles = Vec::with_capacity(t.len() / 3);
    for (i, c) in t.chunks_exact(3).enumerate() {
        let mut tri = [0u32; 3];
        for (slot, &v) in tri.iter_mut().zip(c) {
            if !(v >= 0.0 && v < n as f64 && v.fract() == 0.0) {
                return Err(HeadError::BadIndex {
                    file: file.into(),
                    triangle: i,
                    index: v as i64,
                    vertices: n,
                });
            }
            *slot = v as u32;
        }
        triangles.push(tri);
    }
    let frame = match (&points.data_space, &points.transformed_space) {
        (Some(d), Some(t)) => format!("GIfTI data space {d} (a transform to {t} is given), mm"),
        (Some(d), None) => format!("GIfTI data space {d}, mm"),
        _ => "GIfTI, mm; no coordinate system stated".to_string(),
    };
    Ok((
        Mesh {
            vertices,
            triangles,
        },
        frame,
    ))
}

/// Every `DataArray` of the document.
fn arrays(file: &str, bytes: &[u8]) -> Result<Vec<Array>, HeadError> {
    let mut reader = quick_xml::Reader::from_reader(bytes);
    let mut out = Vec::new();
    let mut current: Option<Array> = None;
    // The element whose text is being read: Data, DataSpace or TransformedSpace.
    let mut text_of: Option<String> = None;
    let mut buf = Vec::new();
    loop {
        let at = reader.buffer_position();
        let event = reader.read_event_into(&mut buf).map_err(|e| {
            HeadError::format(
                file,
                format!("not GIfTI XML: {e}"),
                Some(reader.error_position()),
            )
        })?;
        match event {
            Event::Start(e) => {
                let name = e.name().as_ref().to_string();
                if name == "DataArray" {
                    current = Some(Array {
                        attrs: attributes(&e),
                        offset: at,
                        ..Array::default()
                    });
                } else if current.is_some() {
                    text_of = Some(name);
                }
            }
            Event::Text(t) => {
                if let (Some(a), Some(what)) = (current.as_mut(), text_of.as_deref()) {
                    let s = t.to_string();
                    match what {
                        "Data" => a.data.push_str(&s),
                        "DataSpace" => a.data_space = Some(s.trim().to_string()),
                        "TransformedSpace" => a.transformed_space = Some(s.trim().to_string()),
                        _ => {}
                    }
                }
            }
            Event::CData(t) => {
                if let (Some(a), Some(what)) = (current.as_mut(), text_of.as_deref()) {
                    let s = t.trim().to_string();
                    match what {
                        "DataSpace" => a.data_space = Some(s),
                        "TransformedSpace" => a.transformed_space = Some(s),
                        "Data" => a.data.push_str(&s),
                        _ => {}
                    }
                }
            }
            Event::End(e) => {
                if e.name().as_ref() == "DataArray" {
                    out.extend(current.take());
                }
                text_of = None;
            }
            Event::Empty(e) if e.name().as_ref() == "DataArray" => {
                out.push(Array {
                    attrs: attributes(&e),
                    offset: at,
                    ..Array::default()
                });
            }
            Event::Eof => break,
            _ => {}
        }
        buf.clear();
    }
    Ok(out)
}

/// An array's numbers, row-major, as f64; its declared size checked against `limit` rows.
fn values(file: &str, a: &Array, limit: u64, what: &'static str) -> Result<Vec<f64>, HeadError> {
    let attr = |k: &str| a.attrs.get(k).map(String::as_str).unwrap_or("");
    let bad = |m: String| HeadError::format(file, m, Some(a.offset));
    let dim = |k: &str| -> Result<u64, HeadError> {
        attr(k)
            .parse()
            .map_err(|_| bad(format!("DataArray {k} {:?} is not a count", attr(k))))
    };
    let (rows, cols) = (dim("Dim0")?, dim("Dim1")?);
    if cols != 3 {
        return Err(bad(format!("{what}: Dim1 is {cols}, not 3")));
    }
    let rows = check_count(file, what, rows, limit, None)?;
    let n = rows * 3;
    let size = match attr("DataType") {
        "NIFTI_TYPE_FLOAT32" | "NIFTI_TYPE_INT32" | "NIFTI_TYPE_UINT32" => 4,
        "NIFTI_TYPE_FLOAT64" => 8,
        "NIFTI_TYPE_UINT8" => 1,
        t => return Err(bad(format!("{what}: DataType {t:?} is not read"))),
    };
    let text = a.data.trim();
    let mut v = match attr("Encoding") {
        "ASCII" => {
            let v: Vec<f64> = text
                .split_ascii_whitespace()
                .take(n + 1)
                .map(|w| w.parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| bad(format!("{what}: ASCII data: {e}")))?;
            v
        }
        enc @ ("Base64Binary" | "GZipBase64Binary") => {
            let clean: String = text.split_ascii_whitespace().collect();
            if clean.len() as u64 > (n as u64 * size + 64) * 2 + 1024 {
                return Err(bad(format!(
                    "{what}: {} characters of data for {rows} rows",
                    clean.len()
                )));
            }
            let raw = base64::engine::general_purpose::STANDARD
                .decode(clean.as_bytes())
                .map_err(|e| bad(format!("{what}: base64: {e}")))?;
            let raw = if enc == "GZipBase64Binary" {
                let mut out = Vec::with_capacity(n * size as usize);
                flate2::read::ZlibDecoder::new(&raw[..])
                    .take(n as u64 * size + 1)
                    .read_to_end(&mut out)
                    .map_err(|e| bad(format!("{what}: zlib: {e}")))?;
                out
            } else {
                raw
            };
            decode(&raw, size, attr("DataType"), attr("Endian") == "BigEndian")
        }
        e => return Err(bad(format!("{what}: Encoding {e:?} is not read"))),
    };
    if v.len() != n {
        return Err(bad(format!(
            "{what}: {} values for Dim0 {rows} × 3",
            v.len()
        )));
    }
    if attr("ArrayIndexingOrder") == "ColumnMajorOrder" {
        v = (0..n).map(|i| v[(i % 3) * rows + i / 3]).collect();
    }
    Ok(v)
}

fn decode(raw: &[u8], size: u64, kind: &str, big: bool) -> Vec<f64> {
    raw.chunks_exact(size as usize)
        .map(|c| match (kind, big) {
            ("NIFTI_TYPE_FLOAT32", false) => {
                f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            }
            ("NIFTI_TYPE_FLOAT32", true) => f64::from(f32::from_be_bytes([c[0], c[1], c[2], c[3]])),
            ("NIFTI_TYPE_INT32", false) => f64::from(i32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            ("NIFTI_TYPE_INT32", true) => f64::from(i32::from_be_bytes([c[0], c[1], c[2], c[3]])),
            ("NIFTI_TYPE_UINT32", false) => f64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            ("NIFTI_TYPE_UINT32", true) => f64::from(u32::from_be_bytes([c[0], c[1], c[2], c[3]])),
            ("NIFTI_TYPE_FLOAT64", false) => f64::from_le_bytes(c.try_into().unwrap_or([0; 8])),
            ("NIFTI_TYPE_FLOAT64", true) => f64::from_be_bytes(c.try_into().unwrap_or([0; 8])),
            _ => f64::from(c[0]),
        })
        .collect()
}
