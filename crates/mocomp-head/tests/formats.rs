//! The readers against the writers others made: FreeSurfer's fsaverage head (from MNE-Python),
//! written by trimesh as STL, PLY and OBJ and by nibabel as GIfTI and a FreeSurfer surface, reads
//! back to the same vertices in every format. The peers are required: without them this fails.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::Point3;
use mocomp_head::formats::Format;
use mocomp_head::inspect::inspect;
use mocomp_head::{HeadError, HeadShape, MeshHead};
use mocomp_testkit::{PythonPeer, TempDir};
use serde_json::json;

const PEERS: &str = "mne 1.13.2, nibabel 5.4.2, trimesh 5.2.0";

fn points(v: &serde_json::Value) -> Vec<Point3<f64>> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|p| {
            let c: Vec<f64> = p
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            Point3::new(c[0], c[1], c[2])
        })
        .collect()
}

/// Writes the fsaverage head in `format` (coordinates × `scale`) and returns the file's bytes
/// and the coordinates as the format stores them, in metres.
fn written(
    peer: &mut PythonPeer,
    dir: &TempDir,
    format: &str,
    ext: &str,
    scale: f64,
    encoding: &str,
) -> (String, Vec<u8>, Vec<Point3<f64>>) {
    let path = dir.path(&format!("head-{format}-{encoding}.{ext}"));
    let a = peer.request(&json!({"op": "write", "format": format, "path": path,
        "scale": scale, "encoding": encoding}));
    assert!(a.get("error").is_none(), "{a}");
    let stored = points(&a["vertices"])
        .into_iter()
        .map(|p| p / scale)
        .collect();
    let bytes = std::fs::read(&path).unwrap();
    (path, bytes, stored)
}

#[test]
fn the_fsaverage_head_reads_back_the_same_in_every_format() {
    let mut peer = PythonPeer::start("head_peer.py", "mne, nibabel, trimesh", PEERS);
    let dir = TempDir::new("head-formats");
    let truth = peer.request(&json!({"op": "fsaverage_head"}));
    let n_vertices = truth["vertices_m"].as_array().unwrap().len();
    let n_faces = truth["triangles"].as_array().unwrap().len();
    assert_eq!((n_vertices, n_faces), (2033, 4062));
    let cases = [
        ("stl", "stl", Format::Stl, ""),
        ("stl_ascii", "stl", Format::Stl, ""),
        ("ply", "ply", Format::Ply, ""),
        ("ply_ascii", "ply", Format::Ply, ""),
        ("obj", "obj", Format::Obj, ""),
        ("gii", "gii", Format::Gifti, "GIFTI_ENCODING_B64GZ"),
        ("gii", "gii", Format::Gifti, "GIFTI_ENCODING_B64BIN"),
        ("gii", "gii", Format::Gifti, "GIFTI_ENCODING_ASCII"),
        ("fs", "surf", Format::FreeSurfer, ""),
    ];
    for (format, ext, expect, encoding) in cases {
        let (name, bytes, stored) = written(&mut peer, &dir, format, ext, 1000.0, encoding);
        let unit = expect.unit().is_none().then_some(LengthUnit::Millimetre);
        let (mesh, report) = inspect(&name, &bytes, unit).unwrap_or_else(|e| panic!("{e}"));
        let what = format!("{format} {encoding}");
        assert_eq!(report.format, expect, "{what}");
        assert_eq!(
            (report.vertices, report.faces),
            (n_vertices, n_faces),
            "{what}"
        );
        assert!(report.closed && report.holes == 0, "{what}: {report:?}");
        assert!(!report.repairs.turned_outward, "{what}");
        assert_eq!(report.repairs.flipped_triangles, 0, "{what}");
        // Every stored vertex is one of ours, to the format's own precision.
        for (i, p) in stored.iter().enumerate() {
            let nearest = mesh
                .vertices
                .iter()
                .map(|q| (q - p).norm())
                .fold(f64::INFINITY, f64::min);
            // STL holds float32 (7.6 nm at 100 mm), whatever the text says.
            assert!(
                nearest < 2e-8,
                "{what}: vertex {i} at {p} is {nearest} m from ours"
            );
        }
        let lo = stored
            .iter()
            .fold(Point3::from([f64::INFINITY; 3]), |m, p| m.inf(p));
        let hi = stored
            .iter()
            .fold(Point3::from([f64::NEG_INFINITY; 3]), |m, p| m.sup(p));
        for k in 0..3 {
            assert!((report.bounds_m[0][k] - lo[k]).abs() < 2e-8, "{what}");
            assert!((report.bounds_m[1][k] - hi[k]).abs() < 2e-8, "{what}");
        }
        // The head answers as a head: its centre of mass inside, a point 1 m away outside.
        let head = MeshHead::new(mesh, &name).unwrap();
        let centre = Point3::from(lo.coords.lerp(&hi.coords, 0.5));
        assert!(head.signed_distance(&centre) < -0.05, "{what}");
        assert!((head.signed_distance(&Point3::new(0.0, 0.0, 1.0)) - 0.9).abs() < 0.01);
        if format == "fs" {
            assert!(
                report.frame.contains("c_ras (1.000, -2.000, 3.000)"),
                "{}",
                report.frame
            );
        }
    }
}

/// On a real, non-convex head (nose, chin, ears), the distance field the loop asks is the
/// hierarchy's exact answer everywhere around the scalp, inside and out.
#[test]
fn the_field_is_exact_on_the_fsaverage_head() {
    let mut peer = PythonPeer::start("head_peer.py", "mne, nibabel, trimesh", PEERS);
    let dir = TempDir::new("head-field");
    let (name, bytes, _) = written(&mut peer, &dir, "ply", "ply", 1000.0, "");
    let (mesh, _) = inspect(&name, &bytes, Some(LengthUnit::Millimetre)).unwrap();
    let vertices = mesh.vertices.clone();
    let head = MeshHead::new(mesh, &name).unwrap();
    let mut rng = mocomp_testkit::SplitMix64(31);
    let mut inside = 0;
    for n in 0..3000 {
        // Around a random vertex, up to 40 mm in or out, and in the box around the head.
        let v = vertices[(rng.next_u64() % vertices.len() as u64) as usize];
        let off = mocomp_geom::nalgebra::Vector3::new(
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
        ) * if n % 3 == 0 { 0.08 } else { 0.02 };
        let p = v + off;
        let (field, exact) = (head.signed_distance(&p), head.exact(&p));
        inside += usize::from(exact < 0.0);
        assert!(
            (field - exact).abs() < 1e-9,
            "{p}: field {field}, hierarchy {exact}"
        );
    }
    assert!(inside > 500, "{inside}");
}

#[test]
fn units_are_read_given_or_refused_by_name() {
    let mut peer = PythonPeer::start("head_peer.py", "mne, nibabel, trimesh", PEERS);
    let dir = TempDir::new("head-units");
    let (mm, bytes, _) = written(&mut peer, &dir, "stl", "stl", 1000.0, "");
    let e = inspect(&mm, &bytes, None).unwrap_err();
    assert!(matches!(e, HeadError::UnitsNeeded { .. }), "{e}");
    assert!(
        e.to_string().contains("which is a head in millimetres"),
        "{e}"
    );
    let e = inspect(&mm, &bytes, Some(LengthUnit::Metre)).unwrap_err();
    assert!(
        e.to_string()
            .contains("millimetres read as metres: give --units mm"),
        "{e}"
    );
    let (m, bytes, _) = written(&mut peer, &dir, "stl", "stl", 1.0, "");
    let (_, r) = inspect(&m, &bytes, Some(LengthUnit::Metre)).unwrap();
    assert_eq!(r.unit, "m");
    let e = inspect(&m, &bytes, Some(LengthUnit::Millimetre)).unwrap_err();
    assert!(e.to_string().contains("metres read as millimetres"), "{e}");
    // GIfTI is millimetres by its standard: no unit is asked for.
    let (g, bytes, _) = written(
        &mut peer,
        &dir,
        "gii",
        "gii",
        1000.0,
        "GIFTI_ENCODING_B64GZ",
    );
    let (_, r) = inspect(&g, &bytes, None).unwrap();
    assert!(r.unit_from_format && r.unit == "mm");
}
