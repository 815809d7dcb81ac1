#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! The scalp of a real T1 nobody here made (Colin27: MNI's 27-scan average of one head, 1 mm;
//! tests/data/colin27/SOURCE.md), against the peers (`interop/mri_peer.py`; a missing peer fails
//! the test): scikit-image's marching cubes on our own mask, fsaverage's inner skull from MNE,
//! and the same volume written by nibabel in the other ways NIfTI allows.

use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::{Matrix4, Point3};
use mocomp_head::{HeadShape, Mesh, MeshHead};
use mocomp_mri::{Scalp, SegmentOptions, inspect_volume, read_volume};
use mocomp_testkit::{PythonPeer, TempDir};
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh;
use serde_json::{Value, json};
use std::sync::OnceLock;

const PEERS: &str = "scikit-image 0.26.0, nibabel 5.4.2, mne 1.13.2";

fn colin27_path() -> String {
    concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/colin27/colin27_ch2_1mm.nii.gz"
    )
    .to_string()
}

/// Colin27 segmented with the defaults, once for the file's tests.
fn colin27() -> &'static (Mesh, mocomp_head::inspect::Inspection, Scalp) {
    static ONCE: OnceLock<(Mesh, mocomp_head::inspect::Inspection, Scalp)> = OnceLock::new();
    ONCE.get_or_init(|| {
        let bytes = std::fs::read(colin27_path()).unwrap();
        inspect_volume(
            "colin27.nii.gz",
            &bytes,
            Some(LengthUnit::Millimetre),
            &SegmentOptions::default(),
        )
        .unwrap()
    })
}

fn peer() -> PythonPeer {
    PythonPeer::start("mri_peer.py", "scikit-image, nibabel, mne", PEERS)
}

fn points(v: &Value, key: &str) -> Vec<Point3<f64>> {
    v[key]
        .as_array()
        .unwrap_or_else(|| panic!("no {key}: {v}"))
        .iter()
        .map(|p| {
            Point3::new(
                p[0].as_f64().unwrap(),
                p[1].as_f64().unwrap(),
                p[2].as_f64().unwrap(),
            )
        })
        .collect()
}

fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

#[test]
fn colin27_gives_one_closed_head_sized_scalp_of_the_size_asked_for() {
    let (mesh, inspection, scalp) = colin27();
    let g = inspection.segmentation.as_ref().unwrap();
    assert_eq!(g.threshold_from, "otsu");
    // Background is exactly 0 and the scalp 60–160 (SOURCE.md): the split lies between.
    assert!(g.threshold > 20.0 && g.threshold < 60.0, "{g:?}");
    assert!(inspection.closed && inspection.holes == 0, "{inspection}");
    assert_eq!(
        inspection.repairs.phrases(),
        Vec::<String>::new(),
        "{inspection}"
    );
    assert!(
        mesh.triangles.len() <= 100_000 && mesh.triangles.len() > 95_000,
        "{inspection}"
    );
    assert!(g.isosurface_triangles > 500_000, "{g:?}");
    // The volume's field of view: 181 × 217 × 181 mm from (−90, −125, −71); the head fills
    // its width, a nose and an occiput within its depth, the neck cut at its bottom.
    let [lo, hi] = inspection.bounds_m;
    let mm = |v: f64| v * 1e3;
    assert!((mm(hi[0] - lo[0]) - 181.0).abs() < 3.0, "{inspection}");
    assert!(
        mm(hi[1] - lo[1]) > 195.0 && mm(hi[1] - lo[1]) < 217.0,
        "{inspection}"
    );
    assert!((mm(lo[2]) + 71.0).abs() < 1.0, "the neck cut: {inspection}");
    assert!(
        mm(hi[2]) > 95.0 && mm(hi[2]) < 109.0,
        "the vertex: {inspection}"
    );
    assert_eq!(scalp.frame, "the sform's RAS (MNI152, sform_code 4)");
}

#[test]
fn the_scalp_lies_on_scikit_images_isosurface_of_our_mask_within_a_voxel() {
    let (mesh, _, scalp) = colin27();
    let dir = TempDir::new("mocomp-mri-mc");
    let mask = dir.path("mask.u8");
    std::fs::write(
        &mask,
        scalp
            .mask
            .inside
            .iter()
            .map(|&b| u8::from(b))
            .collect::<Vec<u8>>(),
    )
    .unwrap();
    let mm: Matrix4<f64> = {
        let mut m = scalp.ras_from_voxel;
        m.fixed_view_mut::<3, 4>(0, 0).scale_mut(1e3);
        m
    };
    let rows: Vec<Vec<f64>> = (0..4)
        .map(|r| (0..4).map(|c| mm[(r, c)]).collect())
        .collect();
    let a = peer().request(&json!({
        "op": "marching_cubes", "mask": mask, "dims": scalp.mask.dims, "ras_from_voxel_mm": rows
    }));
    let mc_vertices = points(&a, "vertices_mm");
    let mc_triangles: Vec<[u32; 3]> = a["triangles"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| [0, 1, 2].map(|k| t[k].as_u64().unwrap() as u32))
        .collect();
    let peer_surface = TriMesh::new(mc_vertices.clone(), mc_triangles).unwrap();
    // Every vertex of ours is on the peer's surface to within a voxel (1 mm).
    let ours_to_peer: Vec<f64> = mesh
        .vertices
        .iter()
        .map(|p| peer_surface.distance_to_local_point(&(p * 1e3), true))
        .collect();
    let (median, max) = (
        quantile(ours_to_peer.clone(), 0.5),
        quantile(ours_to_peer, 1.0),
    );
    assert!(
        max < 1.0,
        "ours to scikit-image's: median {median:.3} mm, max {max:.3} mm"
    );
    // And the peer's surface is ours: 99 % of its vertices within a voxel of our surface (the
    // rest are the corners the blur rounds, the nose tip and the rim of the neck cut).
    let ours = TriMesh::new(
        mesh.vertices.iter().map(|p| p * 1e3).collect(),
        mesh.triangles.clone(),
    )
    .unwrap();
    let peer_to_ours: Vec<f64> = mc_vertices
        .iter()
        .step_by(7)
        .map(|p| ours.distance_to_local_point(p, true))
        .collect();
    let (p99, worst) = (
        quantile(peer_to_ours.clone(), 0.99),
        quantile(peer_to_ours, 1.0),
    );
    assert!(
        p99 < 1.0 && worst < 3.0,
        "scikit-image's to ours: p99 {p99:.3} mm, max {worst:.3} mm"
    );
}

#[test]
fn the_scalp_encloses_the_brain() {
    // fsaverage's inner skull (MNE), in FreeSurfer's MRI frame, which is MNI305: a few
    // millimetres from Colin27's MNI152, and the skull's thickness inside the scalp.
    let (mesh, _, _) = colin27();
    let head = MeshHead::new(mesh.clone(), "colin27").unwrap();
    let a = peer().request(&json!({"op": "inner_skull"}));
    let skull = points(&a, "vertices_mm");
    assert!(skull.len() > 10_000);
    // Its lowest part (the foramen magnum, down to z = −72 mm) reaches the scan's bottom edge
    // (z = −71 mm), where the scalp is the cut, not skin: the brain above it is judged.
    let depth: Vec<f64> = skull
        .iter()
        .filter(|p| p.z > -61.0)
        .map(|p| -head.signed_distance(&(p / 1e3)) * 1e3)
        .collect();
    assert!(depth.len() > 9_000, "{}", depth.len());
    let least = quantile(depth.clone(), 0.0);
    let median = quantile(depth, 0.5);
    assert!(
        least > 2.0,
        "the inner skull comes within {least:.2} mm of the scalp"
    );
    assert!(median > 8.0 && median < 30.0, "{median}");
}

/// Reads `path` in metres with the voxels i fastest.
fn volume(path: &str) -> mocomp_mri::Volume {
    read_volume(path, &std::fs::read(path).unwrap(), None).unwrap()
}

#[test]
fn the_volume_reads_the_same_however_nibabel_writes_it() {
    let dir = TempDir::new("mocomp-mri-nibabel");
    let mut p = peer();
    let reference = read_volume(
        "colin27",
        &std::fs::read(colin27_path()).unwrap(),
        Some(LengthUnit::Millimetre),
    )
    .unwrap();
    let [nx, ny, _] = reference.dims;
    for variant in [
        "qform_rotated",
        "las",
        "int16_scaled",
        "float32_nan",
        "metres",
        "plain",
    ] {
        let dst = dir.path(&format!(
            "{variant}.nii{}",
            if variant == "plain" { "" } else { ".gz" }
        ));
        let a = p.request(
            &json!({"op": "resave", "src": colin27_path(), "dst": dst, "variant": variant}),
        );
        let v = volume(&dst);
        assert_eq!(v.dims, reference.dims, "{variant}");
        assert!(v.unit_from_file, "{variant}: nibabel states the unit");
        // The affine as nibabel reads it back (in the file's unit).
        let scale = if variant == "metres" { 1.0 } else { 1e-3 };
        for r in 0..3 {
            for c in 0..4 {
                let theirs = a["ras_from_voxel"][r][c].as_f64().unwrap() * scale;
                assert!(
                    (v.ras_from_voxel[(r, c)] - theirs).abs() < 1e-7,
                    "{variant} [{r}][{c}]"
                );
            }
        }
        // The same intensities at the same places (mirrored back for LAS; NaN read as the
        // least value, 0, which Colin27's background is).
        for (at, &want) in reference.data.iter().enumerate() {
            let (i, j, k) = (at % nx, (at / nx) % ny, at / (nx * ny));
            let src = if variant == "las" {
                (nx - 1 - i) + nx * (j + ny * k)
            } else {
                at
            };
            assert_eq!(v.data[src], want, "{variant} at voxel ({i}, {j}, {k})");
        }
    }
}
