//! The importers on the navigators' own export files (Localite, Brainsight; kept by SimNIBS for
//! its `utils/nnav.py` tests, GPL-3, in `tests/data/navigators/` with the licence), checked
//! against values that do not come from mocomp's importer: the matrices SimNIBS's tests
//! (`utils/tests/test_nnav.py` @ c2ce64cd) state, and the same conventions applied here to the
//! files' raw numbers, read by plain string scanning:
//! - Localite: `M = F · M_file · A`, `F` = diag(−1, −1, 1, 1) when the list's `coordinateSpace` is
//!   LPS, `A` = [[0,0,1],[0,−1,0],[1,0,0]] (its coil x is SimNIBS's z; `nnav.localite`);
//! - Brainsight: the rows' `m0n*`, `m1n*`, `m2n*` are the coil's axes (columns), `Loc.` its
//!   position, its x and z SimNIBS's reversed (`nnav.brainsight`).
//!
//! Files mocomp cannot read (other coordinate systems, other navigators, an empty export) are
//! refused with what they lack named.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::nalgebra::Matrix4;
use mocomp_navfiles::read::{NamedPose, Navigator, parse_poses};
use std::path::PathBuf;

fn path(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/navigators")
        .join(rel)
}

fn read(rel: &str) -> String {
    std::fs::read_to_string(path(rel)).unwrap()
}

fn import(navigator: Navigator, rel: &str) -> Result<Vec<NamedPose>, String> {
    parse_poses(navigator, rel, &read(rel)).map_err(|e| e.to_string())
}

/// A pose as SimNIBS's `matsimnibs`: 4×4, mm.
fn matsimnibs(p: &NamedPose) -> Matrix4<f64> {
    let mut m = p.image_from_coil.to_homogeneous();
    for r in 0..3 {
        m[(r, 3)] *= 1e3;
    }
    m
}

fn assert_close(a: &Matrix4<f64>, b: &Matrix4<f64>, tol: f64, what: &str) {
    let d = (a - b).abs().max();
    assert!(d < tol, "{what}: {d} apart\nmocomp {a}\nexpected {b}");
}

/// The `Matrix4D` elements of a Localite file, in order, by string scanning.
fn localite_raw(text: &str) -> Vec<Matrix4<f64>> {
    text.split("<Matrix4D")
        .skip(1)
        .map(|chunk| {
            let tag = &chunk[..chunk.find("/>").unwrap()];
            Matrix4::from_fn(|r, c| {
                let key = format!("data{r}{c}=\"");
                let from = tag.find(&key).unwrap() + key.len();
                tag[from..from + tag[from..].find('"').unwrap()]
                    .parse()
                    .unwrap()
            })
        })
        .collect()
}

fn localite_convention(m: &Matrix4<f64>, lps: bool) -> Matrix4<f64> {
    let f = if lps {
        Matrix4::from_diagonal(&[-1.0, -1.0, 1.0, 1.0].into())
    } else {
        Matrix4::identity()
    };
    #[rustfmt::skip]
    let a = Matrix4::new(
        0.0, 0.0, 1.0, 0.0,
        0.0, -1.0, 0.0, 0.0,
        1.0, 0.0, 0.0, 0.0,
        0.0, 0.0, 0.0, 1.0,
    );
    f * m * a
}

#[rustfmt::skip]
fn rows(r: [[f64; 4]; 3]) -> Matrix4<f64> {
    Matrix4::new(
        r[0][0], r[0][1], r[0][2], r[0][3],
        r[1][0], r[1][1], r[1][2], r[1][3],
        r[2][0], r[2][1], r[2][2], r[2][3],
        0.0, 0.0, 0.0, 1.0,
    )
}

/// Checks every pose of a Localite file against the convention applied to its raw numbers
/// (untracked markers, written as the identity, left out).
fn check_localite_file(rel: &str, lps: bool) -> Vec<NamedPose> {
    let poses = import(Navigator::Localite, rel).unwrap();
    let raw: Vec<Matrix4<f64>> = localite_raw(&read(rel))
        .into_iter()
        .filter(|m| *m != Matrix4::identity())
        .collect();
    assert_eq!(poses.len(), raw.len(), "{rel}");
    // Localite writes its tracker's rotation, 2e-5 from orthonormal; mocomp makes it so.
    for (k, (p, m)) in poses.iter().zip(&raw).enumerate() {
        assert_close(
            &matsimnibs(p),
            &localite_convention(m, lps),
            1e-4,
            &format!("{rel} #{k}"),
        );
    }
    poses
}

#[test]
fn localite_instrument_markers_in_ras_and_lps() {
    // SimNIBS's test_read_im: six markers, the first "M0".
    let ras = check_localite_file("localite/RAS_InstrumentMarker20170316160859032.xml", false);
    assert_eq!(ras.len(), 6);
    assert_eq!(ras[0].name, "M0");
    let arr_im_0 = rows([
        [
            -4.54280857e-01,
            5.15500953e-01,
            7.26594267e-01,
            -4.18376747e+01,
        ],
        [
            7.82924568e-01,
            6.20186401e-01,
            4.94924946e-02,
            -3.41115599e+01,
        ],
        [
            -4.25099496e-01,
            5.91336751e-01,
            -6.85319504e-01,
            8.86091674e+01,
        ],
    ]);
    assert_close(&matsimnibs(&ras[0]), &arr_im_0, 1e-4, "arr_im_0");
    // SimNIBS's test_read_im_lps: four markers, the first "hotspot", flipped from LPS.
    let lps = check_localite_file("localite/LPS_InstrumentMarker20120925123537421.xml", true);
    assert_eq!(lps.len(), 4);
    assert_eq!(lps[0].name, "hotspot");
    let arr_im_lps_0 = rows([
        [
            -7.47832761e-01,
            5.64773443e-01,
            3.49056141e-01,
            -3.62375709e+01,
        ],
        [
            6.05764663e-01,
            7.95614077e-01,
            1.05110853e-02,
            -3.56913917e+01,
        ],
        [
            -2.71769027e-01,
            2.19299494e-01,
            -9.37076517e-01,
            1.01916610e+02,
        ],
    ]);
    assert_close(&matsimnibs(&lps[0]), &arr_im_lps_0, 1e-4, "arr_im_lps_0");
}

#[test]
fn localite_trigger_markers_and_untracked_pulses() {
    let arr_tm_0 = rows([
        [
            -6.18652573e-01,
            7.39047765e-01,
            2.66519129e-01,
            -2.08740412e+01,
        ],
        [
            7.54371396e-01,
            6.53553556e-01,
            -6.12094487e-02,
            -2.76457908e+01,
        ],
        [
            -2.19426163e-01,
            1.63190693e-01,
            -9.61860701e-01,
            1.02090554e+02,
        ],
    ]);
    // SimNIBS's test_read_tm: eight pulses.
    let tm = check_localite_file("localite/TriggerMarkers_Coil1_20210409170817799.xml", false);
    assert_eq!(tm.len(), 8);
    assert_close(&matsimnibs(&tm[0]), &arr_tm_0, 1e-4, "arr_tm_0");
    // test_read_tm_no_pos: 960 pulses, all but one with the coil out of the camera's view.
    let rel = "localite/no_pos_data_TriggerMarkers_Coil0_20200220155529299.xml";
    assert_eq!(localite_raw(&read(rel)).len(), 960);
    let tracked = check_localite_file(rel, false);
    assert_eq!(tracked.len(), 1);
    assert_close(&matsimnibs(&tracked[0]), &arr_tm_0, 1e-4, "the one tracked");
}

/// The Brainsight rows of `rel` (both tables) and SimNIBS's convention on their raw numbers.
fn brainsight_convention(rel: &str) -> Vec<(String, Matrix4<f64>)> {
    let mut out = Vec::new();
    let mut cols: Option<Vec<String>> = None;
    for line in read(rel).lines() {
        if line.starts_with("# Target Name") || line.starts_with("# Sample Name") {
            cols = Some(line[2..].split('\t').map(str::to_string).collect());
            continue;
        }
        if line.starts_with('#') {
            if line.contains('\t') {
                cols = None;
            }
            continue;
        }
        let Some(c) = &cols else { continue };
        let cells: Vec<&str> = line.split('\t').collect();
        let v = |name: &str| -> f64 {
            cells[c.iter().position(|x| x == name).unwrap()]
                .parse()
                .unwrap()
        };
        // nnav.brainsight._transform_brainsight, then its diag(−1, 1, −1) on the right.
        let m = rows([
            [v("m0n0"), v("m1n0"), v("m2n0"), v("Loc. X")],
            [v("m0n1"), v("m1n1"), v("m2n1"), v("Loc. Y")],
            [v("m0n2"), v("m1n2"), v("m2n2"), v("Loc. Z")],
        ]);
        let flip = Matrix4::from_diagonal(&[-1.0, 1.0, -1.0, 1.0].into());
        out.push((cells[0].to_string(), m * flip));
    }
    out
}

fn check_brainsight_file(rel: &str, targets: usize, samples: usize) -> Vec<NamedPose> {
    let poses = import(Navigator::Brainsight, rel).unwrap();
    let expected = brainsight_convention(rel);
    assert_eq!(poses.len(), targets + samples, "{rel}");
    assert_eq!(expected.len(), poses.len(), "{rel}");
    for (p, (name, m)) in poses.iter().zip(&expected) {
        assert_eq!(&p.name, name);
        // Four decimals in the file: the rotation is made orthonormal on import.
        assert_close(&matsimnibs(p), m, 2e-3, &format!("{rel} {name}"));
    }
    poses
}

#[test]
fn brainsight_exports_in_nifti_aligned() {
    // test_read_nii_niftialigned: 7 targets and 101 samples. SimNIBS's own check of the first
    // sample's matrix has no assert (its np.all is discarded); here it is checked.
    let nii = check_brainsight_file("brainsight/niiImage_niftialignedcoord.txt", 7, 101);
    let arr_sample2 = rows([
        [-7.1200e-01, 3.2100e-01, 6.2400e-01, -4.4198e+01],
        [-1.3000e-02, 8.8300e-01, -4.6900e-01, 7.5810e+01],
        [-7.0200e-01, -3.4200e-01, -6.2400e-01, 6.5742e+01],
    ]);
    // The samples follow the targets.
    let sample1 = &nii[7];
    assert_eq!(sample1.name, "Sample 1");
    assert_close(&matsimnibs(sample1), &arr_sample2, 2e-3, "arr_sample2");
    // test_read_dcm_niftialigned: 1 target and 18 samples (the target is named "Sample 1" too).
    // SimNIBS's stated first sample there (arr_sample1: x −46.889, y 44.464) is this file's
    // row with x and y negated, which its own reader does not do; its test discards the
    // comparison (no assert), so nothing noticed. The file's numbers under the documented
    // convention are what is checked here (above, every row).
    let dcm = check_brainsight_file("brainsight/dcmimage_niftialignedcoord.txt", 1, 18);
    assert_eq!(dcm[1].name, "Sample 1");
    let t = matsimnibs(&dcm[1]).fixed_view::<3, 1>(0, 3).into_owned();
    assert!((t - mocomp_geom::nalgebra::Vector3::new(46.889, -44.464, 73.812)).norm() < 1e-9);
    // Version 14 (Brainsight 2.5.3) names the qform's aligned frame: 2 targets, 3 samples, and
    // a session table after them that is no coil pose.
    let v14 = check_brainsight_file("brainsight/niiImage_niftialigned_q_coord_v14.txt", 2, 3);
    let arr_sample3 = rows([
        [1.0, 0.0, 0.0, 3.2625],
        [0.0, -1.0, 0.0, 66.7014],
        [0.0, 0.0, -1.0, 56.0143],
    ]);
    assert_eq!(v14[2].name, "Sample 1");
    assert_close(&matsimnibs(&v14[2]), &arr_sample3, 1e-9, "arr_sample3");
    // Only targets, only samples.
    check_brainsight_file("brainsight/niiImage_niftialignedcoord_no_samples.txt", 7, 0);
    check_brainsight_file(
        "brainsight/niiImage_niftialignedcoord_no_targets.txt",
        0,
        101,
    );
}

#[test]
fn files_mocomp_cannot_read_are_refused_with_what_they_lack() {
    // Brainsight's other systems are not the image's RAS.
    for (rel, system) in [
        ("brainsight/dcmimage_brainsightcoord.txt", "Brainsight"),
        ("brainsight/dcmimage_worldcoord.txt", "World"),
        ("brainsight/niiImage_brainsightcoord.txt", "Brainsight"),
        ("brainsight/niiImage_nifticoord.txt", "NIfTI:Scanner"),
    ] {
        let e = import(Navigator::Brainsight, rel).unwrap_err();
        assert!(
            e.contains(&format!("{system:?}")) && e.contains("NIfTI:Aligned"),
            "{rel}: {e}"
        );
    }
    let e = import(
        Navigator::Brainsight,
        "brainsight/niiImage_niftialignedcoord_empty.txt",
    )
    .unwrap_err();
    assert!(e.contains("no coil pose"), "{e}");
    // Another navigator's file given as one mocomp reads.
    for (navigator, rel, lacks) in [
        (
            Navigator::Localite,
            "ant/ioJson3DMarker_example_SimNIBS.mrk",
            "InstrumentMarkerList",
        ),
        (
            Navigator::Localite,
            "softaxic/neuronav_coil_test.stmpx",
            "InstrumentMarkerList",
        ),
        (
            Navigator::Brainsight,
            "ant/ioJson3DMarker_example_SimNIBS.mrk",
            "Coordinate system",
        ),
        (
            Navigator::Brainsight,
            "localite/RAS_InstrumentMarker20170316160859032.xml",
            "Coordinate system",
        ),
        (
            Navigator::Localite,
            "brainsight/niiImage_niftialignedcoord.txt",
            "InstrumentMarkerList",
        ),
    ] {
        let e = import(navigator, rel).unwrap_err();
        assert!(
            e.contains(rel) && e.contains(lacks),
            "{rel} as {navigator:?}: {e}"
        );
    }
}
