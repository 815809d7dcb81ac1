#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! A head the scan cuts off: Colin27's T1 (MNI's box ends at both ears and the brow as well as
//! the neck) as `[head] mesh`. The configuration warns of the faces beyond the neck; the head
//! model keeps the patches of the box's faces the head reaches; a goal over the temporal lobe
//! near the ear, where the model is the scan's flat face, is refused by the scan-edge rule, and
//! ones higher over the temporal lobe and over the crown are not.

use mocomp_app::config::Config;
use mocomp_control::{GoalError, HeadModel, check_goal};
use mocomp_geom::nalgebra::{Point3, Vector3};
use mocomp_head::{Head, HeadShape};
use std::path::Path;

fn colin27() -> Config {
    let mut cfg = Config::default();
    let t1 = mocomp_testkit::workspace_root()
        .join("crates/mocomp-mri/tests/data/colin27/colin27_ch2_1mm.nii.gz");
    cfg.head.mesh = Some(t1);
    cfg.head.units = Some("mm".into());
    cfg.head.max_triangles = 20_000;
    cfg.load_head(Path::new("")).unwrap();
    cfg
}

/// The coil 3 mm off the scalp point nearest `towards` (head frame, m), facing it.
fn goal_near(head: &HeadModel, towards: [f64; 3]) -> mocomp_geom::nalgebra::Isometry3<f64> {
    let Head::Mesh(m) = head.shape() else {
        panic!("not a mesh")
    };
    let s = m.nearest(&Point3::from(towards));
    mocomp_testkit::anatomy::coil_facing(&s.point, &s.normal.into_inner(), 0.003, 0.0, 0.0)
}

#[test]
fn a_goal_beside_the_ear_of_a_scan_cut_there_is_refused_and_the_user_warned() {
    let cfg = colin27();
    let head = cfg.loaded.model.clone().unwrap();
    // The planes: the 1 mm box runs from x = -90 to 90, y = -125 to 91, z = -71 to 109 mm;
    // each face lies half a voxel beyond its last voxel's centre, its normal out of the box.
    // Each patch lies in its plane and holds the head's voxels there: the left one, over the
    // ear, spans y from -61.5 to 16.5 mm and z from -71.5 to -14.5 mm.
    let left = head.scan_cuts()[0];
    assert!((left.half_m[0] - 0.039).abs() < 1e-6 && (left.half_m[1] - 0.0285).abs() < 1e-6);
    assert!((left.centre - Point3::new(-0.0905, -0.0225, -0.043)).norm() < 1e-6);
    let planes: Vec<_> = head
        .scan_cuts()
        .iter()
        .map(|c| (c.side, c.centre, c.outward.into_inner()))
        .collect();
    let expect = [
        ("left", 0, -0.0905, -1.0),
        ("right", 0, 0.0905, 1.0),
        ("anterior", 1, 0.0915, 1.0),
        ("inferior", 2, -0.0715, -1.0),
    ];
    assert_eq!(planes.len(), expect.len(), "{planes:?}");
    for ((side, point, outward), (s, axis, at, sign)) in planes.iter().zip(expect) {
        assert_eq!(*side, s);
        assert!((point[axis] - at).abs() < 1e-6, "{side}: {point}");
        let mut n = Vector3::zeros();
        n[axis] = sign;
        assert!((outward - n).norm() < 1e-9, "{side}: {outward}");
    }
    let note = cfg.head_note().expect("a warning");
    assert!(
        note.contains("left, right, anterior faces") && !note.contains("inferior"),
        "{note}"
    );
    let coil = cfg.coil_model();
    let min = cfg.params.goal_min_distance_m();
    // Above the left ear: the scalp and the axis are fine (the rule comes last), but the coil
    // passes 12 mm from where the scan cuts through the ear, and on the cut face itself 3 mm.
    for (towards, nearer_than) in [([-0.1, -0.04, 0.04], 0.015), ([-0.1, -0.02, 0.03], 0.005)] {
        let g = goal_near(&head, towards);
        match check_goal(&head, &coil, &g, min) {
            Err(GoalError::NearScanEdge { side, distance_m }) => {
                assert_eq!(side, "left");
                assert!(distance_m < nearer_than, "{towards:?}: {distance_m}");
            }
            other => panic!("{towards:?}: {other:?}"),
        }
    }
    // Higher over the temporal lobe, 20 mm and more from the cut: accepted.
    for towards in [[-0.1, -0.04, 0.06], [-0.1, -0.02, 0.07]] {
        let g = goal_near(&head, towards);
        assert!(check_goal(&head, &coil, &g, min).is_ok(), "{towards:?}");
    }
    // Over the crown: far inside every cut.
    let crown = goal_near(&head, [0.0, -0.02, 0.2]);
    let d = check_goal(&head, &coil, &crown, min).unwrap();
    // 3 mm less the margin the loop keeps for what the scalp bulges between samples.
    assert!((0.001..0.004).contains(&d), "{d}");
}
