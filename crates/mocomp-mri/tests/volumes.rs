#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! NIfTI volumes made here byte by byte (the NIfTI-1 header's fields at their offsets), good and
//! bad: each bad one is refused with an error that names the field or what is missing, before
//! anything is allocated for what it declares.

use mocomp_geom::LengthUnit;
use mocomp_mri::{MriError, SegmentOptions, inspect_volume, read_volume};
use mocomp_testkit::SplitMix64;
use mocomp_testkit::nifti::Nifti;

/// A head-sized ball: 150 inside 85 mm of the centre, 0 outside, in 64³ voxels of 3 mm.
fn ball() -> Nifti {
    Nifti::cube(64, 3.0, |p| {
        if (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt() < 85.0 {
            150
        } else {
            0
        }
    })
}

fn error(n: &Nifti, unit: Option<LengthUnit>) -> MriError {
    read_volume("test.nii", &n.bytes(), unit).unwrap_err()
}

#[test]
fn a_ball_segments_to_a_closed_sphere_of_its_radius() {
    let (mesh, inspection, scalp) = inspect_volume(
        "ball.nii",
        &ball().bytes(),
        None,
        &SegmentOptions::default(),
    )
    .unwrap();
    assert!(inspection.closed, "{inspection}");
    assert_eq!(inspection.unit, "mm");
    assert!(inspection.unit_from_format, "xyzt_units says millimetres");
    assert_eq!(scalp.frame, "the sform's RAS (scanner, sform_code 1)");
    for p in &mesh.vertices {
        let r = p.coords.norm() * 1e3;
        assert!((r - 85.0).abs() < 2.0, "a vertex {r:.2} mm from the centre");
    }
}

#[test]
fn the_same_file_gzipped_reads_the_same() {
    use std::io::Write;
    let plain = ball().bytes();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(&plain).unwrap();
    let a = read_volume("a.nii", &plain, None).unwrap();
    let b = read_volume("a.nii.gz", &gz.finish().unwrap(), None).unwrap();
    assert_eq!(a.data, b.data);
    assert_eq!(a.ras_from_voxel, b.ras_from_voxel);
}

#[test]
fn a_truncated_volume_says_how_much_is_missing() {
    let mut bytes = ball().bytes();
    bytes.truncate(bytes.len() / 2);
    let e = read_volume("half.nii", &bytes, None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("half.nii") && e.contains("truncated") && e.contains("262144 bytes"),
        "{e}"
    );
    let e = read_volume("header.nii", &bytes[..200], None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("header.nii") && e.contains("not a NIfTI-1 header"),
        "{e}"
    );
}

#[test]
fn a_volume_declaring_too_many_voxels_is_refused_before_reading_them() {
    let mut n = ball();
    n.dim = [3, 30_000, 30_000, 30_000, 1, 1, 1, 1];
    match error(&n, None) {
        MriError::TooLarge { voxels, .. } => assert_eq!(voxels, 27_000_000_000_000),
        e => panic!("{e}"),
    }
}

#[test]
fn bad_header_fields_are_named() {
    type Spoil = fn(&mut Nifti);
    let cases: [(&str, Spoil); 5] = [
        ("dim", |n| n.dim = [4, 64, 64, 64, 2, 1, 1, 1]),
        ("dim", |n| n.dim = [3, 64, 1, 64, 1, 1, 1, 1]),
        ("datatype", |n| {
            n.datatype = 128;
            n.bitpix = 24;
        }),
        ("xyzt_units", |n| n.xyzt_units = 3),
        ("srow_x/srow_y/srow_z", |n| n.sform = Some([[0.0; 4]; 3])),
    ];
    for (field, spoil) in cases {
        let mut n = ball();
        spoil(&mut n);
        match error(&n, None) {
            MriError::Header { field: f, .. } => assert_eq!(f, field),
            e => panic!("{field}: {e}"),
        }
    }
}

#[test]
fn units_are_read_or_given_never_guessed() {
    let mut n = ball();
    n.xyzt_units = 0;
    let e = error(&n, None).to_string();
    assert!(
        e.contains("--units") && e.contains("an MRI voxel in millimetres"),
        "{e}"
    );
    assert!(read_volume("t.nii", &n.bytes(), Some(LengthUnit::Millimetre)).is_ok());
    // Millimetres declared as metres: the head is 170 m across, and the error says what to give.
    let mut n = ball();
    n.xyzt_units = 1;
    let e = inspect_volume("m.nii", &n.bytes(), None, &SegmentOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("millimetres read as metres: give --units mm"),
        "{e}"
    );
    let (_, inspection, scalp) = inspect_volume(
        "m.nii",
        &n.bytes(),
        Some(LengthUnit::Millimetre),
        &SegmentOptions::default(),
    )
    .unwrap();
    assert!(!inspection.unit_from_format);
    assert!(
        scalp
            .frame
            .ends_with("xyzt_units 1 overridden by the unit given"),
        "{}",
        scalp.frame
    );
}

#[test]
fn a_volume_with_no_head_in_it_is_named() {
    let blank = Nifti::cube(32, 6.0, |_| 0);
    let e = inspect_volume(
        "blank.nii",
        &blank.bytes(),
        None,
        &SegmentOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("no head") && e.contains("every voxel holds 0"),
        "{e}"
    );
    let mut rng = SplitMix64(7);
    let noise = Nifti::cube(32, 6.0, |_| (rng.next_u64() % 200) as u8);
    let e = inspect_volume(
        "noise.nii",
        &noise.bytes(),
        None,
        &SegmentOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("no head") && e.contains("faces"), "{e}");
    let e = inspect_volume(
        "high.nii",
        &ball().bytes(),
        None,
        &SegmentOptions {
            threshold: Some(200.0),
            ..SegmentOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("no head") && e.contains("threshold 200"), "{e}");
}
