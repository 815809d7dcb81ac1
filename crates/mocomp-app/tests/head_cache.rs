//! A T1's scalp is segmented once and its field built once, then kept: the next load with the
//! same image and options reads both back (the same surface, cuts, field and distances), other
//! options segment again, and a kept file damaged on disk is passed by and replaced. On
//! Colin27's T1.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_app::files::head::{ScalpFrom, load_head_keeping_in};
use mocomp_control::HeadModel;
use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_head::{Head, HeadShape, MeshHead};
use mocomp_mri::SegmentOptions;
use std::path::{Path, PathBuf};

fn t1() -> PathBuf {
    mocomp_testkit::workspace_root()
        .join("crates/mocomp-mri/tests/data/colin27/colin27_ch2_1mm.nii.gz")
}

fn load(cache: &Path, max_triangles: usize) -> (HeadModel, ScalpFrom) {
    let options = SegmentOptions::new(None, max_triangles).unwrap();
    load_head_keeping_in(
        &t1(),
        Some(LengthUnit::Millimetre),
        &options,
        &Isometry3::translation(0.01, -0.02, 0.03),
        Some(cache),
    )
    .unwrap()
}

fn mesh(head: &HeadModel) -> &MeshHead {
    let Head::Mesh(m) = head.shape() else {
        panic!("not a mesh")
    };
    m
}

/// Flips a byte in the middle of every file in `folder`.
fn damage(folder: &Path) {
    for entry in std::fs::read_dir(folder).unwrap() {
        let path = entry.unwrap().path();
        let mut bytes = std::fs::read(&path).unwrap();
        let middle = bytes.len() / 2;
        bytes[middle] ^= 0x10;
        std::fs::write(&path, bytes).unwrap();
    }
}

#[test]
fn a_segmented_scalp_and_its_field_are_kept_and_read_back_as_they_were() {
    let dir = mocomp_testkit::TempDir::new("head-cache-colin27");
    let cache = PathBuf::from(dir.path(""));
    let (fresh, from) = load(&cache, 20_000);
    assert_eq!(from, ScalpFrom::Segmented);
    let (kept, from) = load(&cache, 20_000);
    assert_eq!(from, ScalpFrom::Kept);
    let (a, b) = (mesh(&fresh), mesh(&kept));
    assert_eq!(a.vertices(), b.vertices());
    assert_eq!(a.triangles(), b.triangles());
    assert_eq!(a.field_grid(), b.field_grid());
    assert_eq!(fresh.scan_cuts(), kept.scan_cuts());
    assert!(!kept.scan_cuts().is_empty());
    for p in [[0.01, 0.02, 0.12], [0.0, 0.0, 0.0], [0.09, -0.01, 0.02]] {
        let p = Point3::from(p);
        assert_eq!(a.signed_distance(&p), b.signed_distance(&p));
        assert_eq!(a.field_value(&p), b.field_value(&p));
    }
    // Another budget is another scalp, and another field.
    let (other, from) = load(&cache, 10_000);
    assert_eq!(from, ScalpFrom::Segmented);
    assert!(mesh(&other).triangles().len() < a.triangles().len());
    assert_eq!(std::fs::read_dir(cache.join("fields")).unwrap().count(), 2);
    // Kept files damaged on disk: segmented and built again, the same, and kept anew.
    damage(&cache.join("scalps"));
    damage(&cache.join("fields"));
    let (again, from) = load(&cache, 20_000);
    assert_eq!(from, ScalpFrom::Segmented);
    assert_eq!(mesh(&again).vertices(), a.vertices());
    assert_eq!(mesh(&again).field_grid(), a.field_grid());
    let (_, from) = load(&cache, 20_000);
    assert_eq!(from, ScalpFrom::Kept);
}
