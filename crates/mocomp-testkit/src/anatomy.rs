//! Real anatomy nobody here made, for tests and benchmarks of the head: FreeSurfer's fsaverage
//! scalp as MNE-Python ships it, through the interop peer (`interop/head_peer.py`; required: a
//! missing peer fails the caller).

use crate::PythonPeer;
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
