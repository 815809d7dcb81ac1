//! Real anatomy nobody here made, for tests and benchmarks of the head: FreeSurfer's fsaverage
//! scalp as MNE-Python ships it, through the interop peer (`interop/head_peer.py`; required: a
//! missing peer fails the caller).

use crate::PythonPeer;
use mocomp_geom::nalgebra::{Isometry3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde_json::json;

/// The peers' versions the head's interop tests pin.
pub const HEAD_PEERS: &str = "mne 1.13.2, nibabel 5.4.2, trimesh 5.2.0";

/// The fsaverage head: vertices (metres, FreeSurfer's MRI frame) and triangles, as MNE reads
/// them (2,033 vertices, 4,062 triangles).
pub fn fsaverage_head() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut peer = PythonPeer::start("head_peer.py", "mne, nibabel, trimesh", HEAD_PEERS);
    let a = peer.request(&json!({"op": "fsaverage_head"}));
    let num = |v: &serde_json::Value| {
        v.as_f64()
            .unwrap_or_else(|| panic!("head peer: {v} is not a number"))
    };
    let list = |key: &str| {
        a[key]
            .as_array()
            .unwrap_or_else(|| panic!("head peer: no {key} in its answer"))
            .clone()
    };
    let vertices = list("vertices_m")
        .iter()
        .map(|p| [num(&p[0]), num(&p[1]), num(&p[2])])
        .collect();
    let triangles = list("triangles")
        .iter()
        .map(|t| [0, 1, 2].map(|k| num(&t[k]) as u32))
        .collect();
    (vertices, triangles)
}

/// Writes the fsaverage head to `path` as the head peer writes `format` ("ply", "stl", "obj",
/// "gii", "fs", …), its coordinates in millimetres.
pub fn write_fsaverage(path: &str, format: &str) {
    let mut peer = PythonPeer::start("head_peer.py", "mne, nibabel, trimesh", HEAD_PEERS);
    let a = peer.request(&json!({"op": "write", "format": format, "path": path, "scale": 1000.0}));
    assert!(a.get("error").is_none(), "head peer: {a}");
}

/// A coil facing a surface at `point` with outward `normal`: its +z along the inward normal,
/// turned by `spin` about it and tilted by `tilt` about its own x, its face `gap` off the point
/// along the normal (negative: inside).
pub fn coil_facing(
    point: &Point3<f64>,
    normal: &Vector3<f64>,
    gap: f64,
    tilt: f64,
    spin: f64,
) -> Isometry3<f64> {
    let z = -normal;
    let x = z
        .cross(&Vector3::x())
        .try_normalize(1e-6)
        .unwrap_or_else(Vector3::y);
    let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_basis_unchecked(&[
        x,
        z.cross(&x),
        z,
    ])) * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spin)
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt);
    Isometry3::from_parts(Translation3::from(point.coords + normal * gap), r)
}

/// MNE's fsaverage fiducials (`nasion`, `lpa`, `rpa`) and the positions of its `montage`
/// (`fsaverage_1020`, `_1010`, `_1005`: `F3`, `C3`, …), the head's frame, metres.
pub fn fsaverage_points(
    montage: &str,
) -> (
    std::collections::BTreeMap<String, Point3<f64>>,
    std::collections::BTreeMap<String, Point3<f64>>,
) {
    let mut peer = PythonPeer::start("head_peer.py", "mne, nibabel, trimesh", HEAD_PEERS);
    let a = peer.request(&json!({"op": "fsaverage_points", "montage": montage}));
    let table = |key: &str| {
        a[key]
            .as_object()
            .unwrap_or_else(|| panic!("head peer: no {key} in its answer: {a}"))
            .iter()
            .map(|(name, p)| {
                let c = |k: usize| {
                    p[k].as_f64()
                        .unwrap_or_else(|| panic!("head peer: {name}: {p} is not a point"))
                };
                (name.clone(), Point3::new(c(0), c(1), c(2)))
            })
            .collect()
    };
    (table("fiducials_m"), table("eeg_m"))
}
