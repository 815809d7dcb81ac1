//! Bad files get a named error and never a panic, a hang or an allocation the file did not pay
//! for: truncated, oversized, non-finite, out of range, the wrong unit, and bytes mutated at
//! random (a seeded fuzz of every decoder).
#![allow(clippy::unwrap_used)] // test code

use super::*;
use crate::mesh::tests::ellipsoid_mesh;
use mocomp_geom::nalgebra::Vector3;
use proptest::prelude::*;

/// A head-sized ellipsoid, in millimetres.
fn head_mm() -> Mesh {
    ellipsoid_mesh(&Vector3::new(75.0, 95.0, 110.0), 2)
}

fn binary_stl(m: &Mesh, declared: Option<u32>) -> Vec<u8> {
    let mut out = vec![0u8; 80];
    out.extend_from_slice(&declared.unwrap_or(m.triangles.len() as u32).to_le_bytes());
    for t in &m.triangles {
        out.extend_from_slice(&[0u8; 12]);
        for &i in t {
            for c in m.vertices[i as usize].iter() {
                out.extend_from_slice(&(*c as f32).to_le_bytes());
            }
        }
        out.extend_from_slice(&[0, 0]);
    }
    out
}

fn ascii_stl(m: &Mesh) -> String {
    let mut s = String::from("solid head\n");
    for t in &m.triangles {
        s += "facet normal 0 0 0\nouter loop\n";
        for &i in t {
            let v = m.vertices[i as usize];
            s += &format!("vertex {} {} {}\n", v.x, v.y, v.z);
        }
        s += "endloop\nendfacet\n";
    }
    s + "endsolid head\n"
}

fn obj(m: &Mesh) -> String {
    let mut s = String::new();
    for v in &m.vertices {
        s += &format!("v {} {} {}\n", v.x, v.y, v.z);
    }
    for t in &m.triangles {
        s += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    s
}

fn gifti(m: &Mesh, dim0_points: Option<usize>) -> String {
    let p: Vec<String> = m
        .vertices
        .iter()
        .map(|v| format!("{} {} {}", v.x, v.y, v.z))
        .collect();
    let t: Vec<String> = m
        .triangles
        .iter()
        .map(|t| format!("{} {} {}", t[0], t[1], t[2]))
        .collect();
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<GIFTI Version="1.0" NumberOfDataArrays="2">
<DataArray Intent="NIFTI_INTENT_POINTSET" DataType="NIFTI_TYPE_FLOAT32" ArrayIndexingOrder="RowMajorOrder" Dimensionality="2" Dim0="{}" Dim1="3" Encoding="ASCII" Endian="LittleEndian">
<CoordinateSystemTransformMatrix><DataSpace><![CDATA[NIFTI_XFORM_TALAIRACH]]></DataSpace><TransformedSpace><![CDATA[NIFTI_XFORM_TALAIRACH]]></TransformedSpace><MatrixData>1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1</MatrixData></CoordinateSystemTransformMatrix>
<Data>{}</Data></DataArray>
<DataArray Intent="NIFTI_INTENT_TRIANGLE" DataType="NIFTI_TYPE_INT32" ArrayIndexingOrder="RowMajorOrder" Dimensionality="2" Dim0="{}" Dim1="3" Encoding="ASCII" Endian="LittleEndian"><Data>{}</Data></DataArray>
</GIFTI>"#,
        dim0_points.unwrap_or(m.vertices.len()),
        p.join("\n"),
        m.triangles.len(),
        t.join("\n")
    )
}

/// Every format, valid, as (file name, bytes).
fn files() -> Vec<(&'static str, Vec<u8>)> {
    let m = head_mm();
    vec![
        ("head.stl", binary_stl(&m, None)),
        ("ascii.stl", ascii_stl(&m).into_bytes()),
        ("head.obj", obj(&m).into_bytes()),
        ("head.ply", write_ply(&m, 1.0).unwrap()),
        ("head.gii", gifti(&m, None).into_bytes()),
        ("lh.seghead", freesurfer::write(&m, "")),
    ]
}

#[test]
fn every_format_reads_our_own_files() {
    let m = head_mm();
    for (name, bytes) in files() {
        let s = read_surface(name, &bytes, Some(LengthUnit::Millimetre)).unwrap();
        let (mesh, r) = crate::repair(s.mesh, name).unwrap();
        assert_eq!(mesh.triangles.len(), m.triangles.len(), "{name}");
        assert!(r.closed_as_read && !r.turned_outward, "{name} {r:?}");
    }
    let s = read_surface("head.gii", &files()[4].1, None).unwrap();
    assert!(s.frame.contains("NIFTI_XFORM_TALAIRACH"), "{}", s.frame);
}

#[test]
fn declared_sizes_beyond_the_limit_are_refused_before_reading() {
    let m = head_mm();
    // Ten million triangles declared in a file of a few kilobytes.
    let e = read_surface(
        "big.stl",
        &binary_stl(&m, Some(10_000_000)),
        Some(LengthUnit::Millimetre),
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            HeadError::TooLarge {
                count: 10_000_000,
                ..
            }
        ),
        "{e}"
    );
    let ply = String::from_utf8_lossy(&write_ply(&m, 1.0).unwrap())
        .into_owned()
        .replacen(
            &format!("element face {}", m.triangles.len()),
            "element face 10000000",
            1,
        );
    let e = read_surface("big.ply", ply.as_bytes(), Some(LengthUnit::Millimetre)).unwrap_err();
    assert!(
        e.to_string()
            .contains("10000000 faces, more than the 5000000"),
        "{e}"
    );
    let mut fs = freesurfer::write(&m, "");
    let at = fs.windows(2).position(|w| w == b"\n\n").unwrap() + 2;
    fs[at..at + 4].copy_from_slice(&10_000_000u32.to_be_bytes());
    let e = read_surface("lh.seghead", &fs, None).unwrap_err();
    assert!(e.to_string().contains("10000000 vertices"), "{e}");
    let e = read_surface("big.gii", gifti(&m, Some(10_000_000)).as_bytes(), None).unwrap_err();
    assert!(e.to_string().contains("10000000 vertices"), "{e}");
}

#[test]
fn truncated_and_broken_files_are_named() {
    let m = head_mm();
    let stl = binary_stl(&m, None);
    let e = read_surface(
        "cut.stl",
        &stl[..stl.len() - 30],
        Some(LengthUnit::Millimetre),
    )
    .unwrap_err();
    assert!(e.to_string().contains("cut.stl: it declares"), "{e}");
    assert!(e.to_string().contains("truncated"), "{e}");
    let fs = freesurfer::write(&m, "");
    let e = read_surface("lh.seghead", &fs[..fs.len() - 7], None).unwrap_err();
    assert!(e.to_string().contains("truncated"), "{e}");
    let e = read_surface("lh.seghead", &fs[..20], None).unwrap_err();
    assert!(e.to_string().starts_with("lh.seghead:"), "{e}");
    let text = ascii_stl(&m).replacen("vertex ", "vertex nan ", 1);
    let e = read_surface("nan.stl", text.as_bytes(), Some(LengthUnit::Millimetre))
        .and_then(|s| crate::repair(s.mesh, "nan.stl").map(|_| ()))
        .unwrap_err();
    assert!(e.to_string().starts_with("nan.stl:"), "{e}");
    let bad = obj(&m) + "f 1 2 99999\n";
    let e = read_surface("bad.obj", bad.as_bytes(), Some(LengthUnit::Millimetre))
        .and_then(|s| crate::repair(s.mesh, "bad.obj").map(|_| ()))
        .unwrap_err();
    assert!(e.to_string().starts_with("bad.obj:"), "{e}");
    let e = read_surface("head.vtk", b"# vtk DataFile", None).unwrap_err();
    assert!(
        e.to_string().contains("not a head file mocomp reads"),
        "{e}"
    );
    // A volume is detected, and left to the segmentation (mocomp-mri), not decoded here.
    let e = read_surface("head.nii", b"\x5c\x01\0\0", None).unwrap_err();
    assert!(e.to_string().contains("a volume, not a surface"), "{e}");
    let g = gifti(&m, None).replace("Encoding=\"ASCII\"", "Encoding=\"Base64Binary\"");
    let e = read_surface("b.gii", g.as_bytes(), None).unwrap_err();
    assert!(e.to_string().contains("base64"), "{e}");
}

#[test]
fn a_head_the_wrong_size_is_refused() {
    let tiny = ellipsoid_mesh(&Vector3::new(0.75, 0.95, 1.1), 1);
    let e = read_surface(
        "tiny.obj",
        obj(&tiny).as_bytes(),
        Some(LengthUnit::Millimetre),
    )
    .unwrap_err();
    assert!(e.to_string().contains("this is not a head"), "{e}");
    let e = read_surface(
        "huge.obj",
        obj(&head_mm()).as_bytes(),
        Some(LengthUnit::Metre),
    )
    .unwrap_err();
    assert!(
        e.to_string().contains("0.220 m across") || e.to_string().contains("220.000 m"),
        "{e}"
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, rng_seed: proptest::test_runner::RngSeed::Fixed(31), ..ProptestConfig::default() })]
    /// Any file with bytes changed, cut or added reads or fails with an error, never a panic.
    #[test]
    fn mutated_files_never_panic(
        which in 0usize..6,
        edits in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..8),
        cut in any::<prop::sample::Index>(),
        truncate in any::<bool>(),
    ) {
        let (name, mut bytes) = files().swap_remove(which);
        for (at, b) in edits {
            let i = at.index(bytes.len());
            bytes[i] = b;
        }
        if truncate {
            bytes.truncate(cut.index(bytes.len()));
        }
        if let Ok(s) = read_surface(name, &bytes, Some(LengthUnit::Millimetre)) {
            let _ = crate::repair(s.mesh, name);
        }
    }
}
