#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! The experiment on a real head: FreeSurfer's fsaverage scalp (from MNE-Python through the
//! interop peer, required) read from a PLY file as `[head] mesh`, the phantom the head robot
//! moves and the head model mocomp keeps the coil from, with the goal over the forehead beside
//! the brow. Believing the scalp, mocomp's true coil never enters it; believing the ellipsoid
//! fitted to that scalp (the goal planned on the ellipsoid, as a clinician plans on the model
//! they have), the same loop puts the coil into the brow. With SimNIBS's Magstim D70 casing as
//! the coil's solid (`[coil] casing`), the held casing never enters fsaverage's scalp nor
//! Colin27's (segmented from its T1), however the head nods.

use mocomp_app::config::{Config, LoopHead};
use mocomp_app::experiment::{Controller, run_experiment};
use mocomp_control::{CoilModel, GoalError, check_goal};
use mocomp_geom::nalgebra::Point3;
use mocomp_head::{Head, HeadShape};
use mocomp_testkit::TempDir;
use mocomp_testkit::anatomy::coil_facing;
use std::net::IpAddr;
use std::path::Path;

fn fsaverage_ply(dir: &TempDir) -> String {
    let path = dir.path("fsaverage-head.ply");
    mocomp_testkit::anatomy::write_fsaverage(&path, "ply");
    path
}

/// mocomp alone for 8 s of the default motion, the goal over the brow, on `loop_head`.
fn run(mesh: &str, loop_head: LoopHead, hosts: [u8; 2]) -> (f64, f64) {
    let mut cfg = Config::default();
    cfg.head.mesh = Some(mesh.into());
    cfg.head.units = Some("mm".into());
    cfg.load_head(Path::new("")).unwrap();
    cfg.experiment.goal_near_mm = Some([30.0, 90.0, 40.0]);
    cfg.experiment.loop_head = loop_head;
    run_config(cfg, hosts)
}

/// `cfg`'s experiment, mocomp alone for 8 s of the default motion: the least true clearance
/// (m) and the time the coil spent inside the head (s).
fn run_config(mut cfg: Config, hosts: [u8; 2]) -> (f64, f64) {
    let loop_head = cfg.experiment.loop_head;
    cfg.experiment.duration_s = 8.0;
    let mut exp = mocomp_app::demo::experiment_config::from_config(&cfg).unwrap();
    exp.coil_host = IpAddr::from([127, 0, 0, hosts[0]]);
    exp.head_host = IpAddr::from([127, 0, 0, hosts[1]]);
    let out = run_experiment(&exp, &[Controller::Mocomp], &mut |_, _| {}).unwrap();
    let r = &out.runs[0];
    eprintln!(
        "{loop_head:?}: d RMS {:.3}, max {:.3}; least true clearance {:.2} mm, {:.2} s inside",
        r.d.rms,
        r.d.max,
        r.min_clearance_m * 1e3,
        r.inside_head_s
    );
    assert!(r.d.rms < 1.0, "{}", r.d.rms);
    (r.min_clearance_m, r.inside_head_s)
}

#[test]
fn on_its_own_scalp_the_coil_never_enters_it_and_on_the_fitted_ellipsoid_it_does() {
    let dir = TempDir::new("head-mesh-demo");
    let mesh = fsaverage_ply(&dir);
    let (clear, inside) = run(&mesh, LoopHead::Head, [121, 122]);
    assert!(clear > 0.001 && inside == 0.0, "{clear} {inside}");
    let (clear_e, inside_e) = run(&mesh, LoopHead::FittedEllipsoid, [123, 124]);
    assert!(clear_e < 0.0 && inside_e > 1.0, "{clear_e} {inside_e}");
}

/// SimNIBS's Magstim D70 casing as `[coil] casing` (its path; the file is in mm, coil frame).
fn d70_casing() -> std::path::PathBuf {
    mocomp_testkit::workspace_root().join("crates/mocomp-efield/tests/data/coils/MagStim_D70.stl")
}

#[test]
fn the_d70_s_casing_held_over_fsaverage_s_brow_never_enters_the_scalp() {
    let dir = TempDir::new("head-mesh-casing");
    let mut cfg = Config::default();
    cfg.head.mesh = Some(fsaverage_ply(&dir).into());
    cfg.head.units = Some("mm".into());
    cfg.coil.casing = Some(d70_casing());
    cfg.load_head(Path::new("")).unwrap();
    assert!(cfg.coil.loaded_casing.is_some());
    cfg.experiment.goal_near_mm = Some([30.0, 90.0, 40.0]);
    let (clear, inside) = run_config(cfg, [160, 161]);
    assert!(clear > 0.0005 && inside == 0.0, "{clear} {inside}");
}

#[test]
fn the_d70_s_casing_held_over_colin27_s_motor_cortex_never_enters_the_scalp() {
    let mut cfg = Config::default();
    cfg.head.mesh = Some(
        mocomp_testkit::workspace_root()
            .join("crates/mocomp-mri/tests/data/colin27/colin27_ch2_1mm.nii.gz"),
    );
    cfg.head.units = Some("mm".into());
    cfg.head.max_triangles = 20_000;
    cfg.coil.casing = Some(d70_casing());
    cfg.load_head(Path::new("")).unwrap();
    // The casing, not the cylinder, is what the scan-edge rule keeps from where the scan ends:
    // over the forehead, 30 mm behind the face of MNI's box that cuts the head at the brow,
    // the cylinder 5 mm off the scalp is allowed and the casing's wings (100 mm each way) are
    // not.
    let head = cfg.loaded.model.clone().unwrap();
    let Head::Mesh(m) = head.shape() else {
        panic!("not a mesh")
    };
    let s = m.nearest(&Point3::new(0.03, 0.06, 0.07));
    let brow = coil_facing(&s.point, &s.normal.into_inner(), 0.005, 0.0, 0.0);
    let cylinder = CoilModel::cylinder(cfg.coil.radius_m, cfg.coil.thickness_m);
    let by_cylinder = check_goal(&head, &cylinder, &brow, 0.002);
    assert!(by_cylinder.is_ok(), "{by_cylinder:?}");
    match check_goal(&head, &cfg.coil_model(), &brow, 0.002) {
        Err(GoalError::NearScanEdge { side, distance_m }) => {
            eprintln!(
                "the casing over the forehead: {:.1} mm from the {side} cut",
                distance_m * 1e3
            );
            assert_eq!(side, "anterior");
        }
        other => panic!("{other:?}"),
    }
    // Over the right motor cortex (MNI), its wings over the crown and the temple, it is held.
    cfg.experiment.goal_near_mm = Some([50.0, -10.0, 90.0]);
    let (clear, inside) = run_config(cfg, [162, 163]);
    assert!(clear > 0.0005 && inside == 0.0, "{clear} {inside}");
}
