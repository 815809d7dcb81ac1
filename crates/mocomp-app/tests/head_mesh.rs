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
//! they have), the same loop puts the coil into the brow.

use mocomp_app::config::{Config, LoopHead};
use mocomp_app::experiment::{Controller, run_experiment};
use mocomp_testkit::TempDir;
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
    cfg.experiment.duration_s = 8.0;
    let mut exp = mocomp_app::experiment_config::from_config(&cfg).unwrap();
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
