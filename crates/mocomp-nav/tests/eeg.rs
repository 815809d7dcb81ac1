//! The 10-20 and 10-10 positions on a real scalp: FreeSurfer's fsaverage head (from MNE through
//! the interop peer, required), from its fiducials (fsaverage-fiducials.fif) and the inion of
//! MNE's 10-05 montage (Iz), against MNE's own fsaverage montages, which were placed on that head
//! by other hands.
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_head::{HeadShape, Mesh, MeshHead, repair};
use mocomp_nav::{CranialLandmarks, System, eeg_positions};

fn fsaverage(place: &Isometry3<f64>) -> MeshHead {
    let (v, t) = mocomp_testkit::anatomy::fsaverage_head();
    let raw = Mesh {
        vertices: v.iter().map(|p| place * Point3::from(*p)).collect(),
        triangles: t,
    };
    let (mesh, _) = repair(raw, "fsaverage").unwrap();
    MeshHead::new(mesh, "fsaverage").unwrap()
}

fn landmarks() -> CranialLandmarks {
    let (fid, eeg) = mocomp_testkit::anatomy::fsaverage_points("fsaverage_1005");
    CranialLandmarks {
        nasion: fid["nasion"],
        inion: eeg["Iz"],
        lpa: fid["lpa"],
        rpa: fid["rpa"],
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn the_10_20_positions_on_fsaverage_agree_with_mne_s_montage() {
    let scalp = fsaverage(&Isometry3::identity());
    let (_, mut mne) = mocomp_testkit::anatomy::fsaverage_points("fsaverage_1020");
    // The montage's own fiducial rows.
    mne.retain(|k, _| !["NAS", "LPA", "RPA"].contains(&k.as_str()));
    let ours = eeg_positions(&scalp, &landmarks(), System::TenTwenty).unwrap();
    assert_eq!(
        ours.len(),
        mne.len(),
        "MNE's 10-20 has {} positions",
        mne.len()
    );
    let mut apart = Vec::new();
    let mut along_scalp = Vec::new();
    for p in &ours {
        let theirs = mne
            .get(p.name)
            .unwrap_or_else(|| panic!("MNE has no {}", p.name));
        let d = (p.point - theirs).norm();
        // MNE's positions were placed on a finer scalp than this 2,033-vertex one: on the scalp
        // here they lie where the nearest point is.
        let on = scalp.nearest(theirs);
        let along = (p.point - on.point).norm();
        eprintln!(
            "{:>4}: ours ({:6.1}, {:6.1}, {:6.1}) mm, MNE's ({:6.1}, {:6.1}, {:6.1}) mm ({:+.1} mm off this scalp), {:4.1} mm apart, {:4.1} along the scalp",
            p.name,
            p.point.x * 1e3,
            p.point.y * 1e3,
            p.point.z * 1e3,
            theirs.x * 1e3,
            theirs.y * 1e3,
            theirs.z * 1e3,
            on.signed_distance * 1e3,
            d * 1e3,
            along * 1e3,
        );
        assert!(
            scalp.signed_distance(&p.point).abs() < 1e-4,
            "{} is off the scalp",
            p.name
        );
        apart.push((p.name, d));
        along_scalp.push(along);
    }
    let d = |n: &str| apart.iter().find(|(m, _)| *m == n).unwrap().1;
    let all: Vec<f64> = apart.iter().map(|(_, d)| *d).collect();
    let max = all.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "10-20 on fsaverage against MNE: F3 {:.1}, C3 {:.1}, Cz {:.1} mm apart; median {:.1}, max {:.1} mm; along the scalp median {:.1}, max {:.1} mm",
        d("F3") * 1e3,
        d("C3") * 1e3,
        d("Cz") * 1e3,
        median(all.clone()) * 1e3,
        max * 1e3,
        median(along_scalp.clone()) * 1e3,
        along_scalp.iter().copied().fold(0.0, f64::max) * 1e3,
    );
    // Electrodes of one 10-20 cap sit ~40–70 mm apart: a position off by one place, or
    // mirrored, is tens of millimetres away. MNE's T7 and T8 lie 8–10 mm anterior of where the
    // central curve through the preauricular points puts them.
    let along = |n: &str| along_scalp[apart.iter().position(|(m, _)| *m == n).unwrap()];
    for (name, within) in [("F3", 0.005), ("C3", 0.005), ("Cz", 0.003)] {
        assert!(
            d(name) < 0.008,
            "{name} is {:.1} mm from MNE's",
            d(name) * 1e3
        );
        assert!(
            along(name) < within,
            "{name} is {:.1} mm from MNE's",
            along(name) * 1e3
        );
    }
    assert!(median(along_scalp.clone()) < 0.004 && max < 0.012);
}

#[test]
fn the_10_10_positions_on_fsaverage_agree_with_mne_s_montage() {
    let scalp = fsaverage(&Isometry3::identity());
    let (_, mne) = mocomp_testkit::anatomy::fsaverage_points("fsaverage_1010");
    let ours = eeg_positions(&scalp, &landmarks(), System::TenTen).unwrap();
    assert_eq!(ours.len(), 61);
    let mut along = Vec::new();
    let mut missing = Vec::new();
    for p in &ours {
        match mne.get(p.name) {
            Some(theirs) => along.push((p.point - scalp.nearest(theirs).point).norm()),
            None => missing.push(p.name),
        }
    }
    let worst = along.iter().copied().fold(0.0, f64::max);
    eprintln!(
        "10-10 on fsaverage against MNE: {} positions in both, along the scalp median {:.1}, max {:.1} mm; not in MNE's: {}",
        along.len(),
        median(along.clone()) * 1e3,
        worst * 1e3,
        missing.join(", ")
    );
    assert!(
        along.len() >= 55,
        "only {} positions in common",
        along.len()
    );
    assert!(median(along) < 0.005 && worst < 0.012);
}
