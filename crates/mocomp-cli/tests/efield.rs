//! `mocomp efield` against physics nobody here wrote: MNE-Python's sphere-model magnetic field of
//! a current dipole (Sarvas 1987; `interop/efield_peer.py`, required: without it this fails). By
//! reciprocity E(r)·p = −dI/dt Σ mᵢ·B_p(rᵢ): MNE's field of a unit dipole at each target, summed
//! over the coil's dipoles, is the coil's field there. Both of SimNIBS's coil models, 1,000
//! random targets and poses each, on spheres of random centre and radius. The coil's dipoles are
//! placed for MNE here, from the 16 numbers given to `mocomp`, with nothing of mocomp's.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_testkit::{PythonPeer, SplitMix64, TempDir, workspace_root};
use serde_json::{Value, json};

mod common;
use common::{assert_success, mocomp};

const PEER: &str = "mne 1.13.2";

/// A coil file's dipoles and moments, read here as rows of six numbers after three lines.
fn dipoles(path: &std::path::Path) -> Vec<[f64; 6]> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(3)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3], v[4], v[5]]
        })
        .collect()
}

/// A rotation matrix from a random unit quaternion.
fn random_rotation(rng: &mut SplitMix64) -> [[f64; 3]; 3] {
    let (u1, u2, u3) = (rng.next_f64(), rng.next_f64(), rng.next_f64());
    let tau = std::f64::consts::TAU;
    let (w, x, y, z) = (
        (1.0 - u1).sqrt() * (tau * u2).sin(),
        (1.0 - u1).sqrt() * (tau * u2).cos(),
        u1.sqrt() * (tau * u3).sin(),
        u1.sqrt() * (tau * u3).cos(),
    );
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

fn apply(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

#[test]
fn mocomp_efield_is_mnes_reciprocal_field_on_both_coils() {
    let mut peer = PythonPeer::start("efield_peer.py", "mne", PEER);
    let dir = TempDir::new("efield-mne");
    let coils = workspace_root().join("crates/mocomp-efield/tests/data/coils");
    // The D70 at its file's full output; the legacy coil (no dIdtmax) at a given 80 A/µs.
    for (name, didt_a_per_us, seed) in [
        ("MagStim_D70.ccd", None, 1u64),
        ("Magstim_70mm_Fig8.ccd", Some(80.0), 2),
    ] {
        let path = coils.join(name);
        let coil = dipoles(&path);
        let didt = didt_a_per_us.unwrap_or(114.73) * 1e6;
        let mut rng = SplitMix64(seed);
        let (mut worst, mut compared) = (0.0f64, 0usize);
        for pose_k in 0..20 {
            // A sphere of 70–95 mm somewhere near the origin.
            let centre_m = [0, 1, 2].map(|_| 0.04 * (rng.next_f64() - 0.5));
            let radius_m = 0.07 + 0.025 * rng.next_f64();
            // A coil facing the sphere's centre from a random direction, turned anywhere about
            // its axis, its face 1–20 mm off the surface.
            let rot = random_rotation(&mut rng);
            let z_axis = [rot[0][2], rot[1][2], rot[2][2]];
            // Place the coil's origin on the line through the centre opposite its +z.
            let gap = 0.001 + 0.019 * rng.next_f64();
            let origin = [0, 1, 2].map(|i| centre_m[i] - z_axis[i] * (radius_m + gap));
            let mut m = [0.0; 16];
            for i in 0..3 {
                for j in 0..3 {
                    m[4 * i + j] = rot[i][j];
                }
                m[4 * i + 3] = origin[i] * 1e3;
            }
            m[15] = 1.0;
            // Targets 5–40 mm under the coil's centre, up to 20 mm off its axis, inside the
            // sphere by 1 mm.
            let mut targets_m = Vec::new();
            while targets_m.len() < 50 {
                let local = [
                    0.04 * (rng.next_f64() - 0.5),
                    0.04 * (rng.next_f64() - 0.5),
                    gap + 0.005 + 0.035 * rng.next_f64(),
                ];
                let p = apply(&rot, local);
                let p = [0, 1, 2].map(|i| p[i] + origin[i]);
                if norm([0, 1, 2].map(|i| p[i] - centre_m[i])) < radius_m - 0.001 {
                    targets_m.push(p);
                }
            }
            let csv = dir.path(&format!("{name}-{pose_k}.csv"));
            let mut text = String::from("x_mm,y_mm,z_mm\n");
            for p in &targets_m {
                text += &format!("{},{},{}\n", p[0] * 1e3, p[1] * 1e3, p[2] * 1e3);
            }
            std::fs::write(&csv, text).unwrap();
            let pose = m.map(|v| v.to_string()).join(",");
            let sphere = format!(
                "{},{},{},{}",
                centre_m[0] * 1e3,
                centre_m[1] * 1e3,
                centre_m[2] * 1e3,
                radius_m * 1e3
            );
            let coil_arg = path.display().to_string();
            let mut args = vec![
                "efield", "--coil", &coil_arg, "--pose", &pose, "--sphere", &sphere, "--points",
                &csv, "--json",
            ];
            let didt_arg = didt_a_per_us.map(|d: f64| d.to_string());
            if let Some(d) = &didt_arg {
                args.extend(["--didt", d]);
            }
            let out = mocomp(&args);
            assert_success(&out);
            let ours: Value = serde_json::from_slice(&out.stdout).unwrap();
            let ours = ours["points"].as_array().unwrap();
            assert_eq!(ours.len(), targets_m.len());
            // The coil's dipoles in the head frame, by the matrix's own arithmetic.
            let (placed, moments): (Vec<[f64; 3]>, Vec<[f64; 3]>) = coil
                .iter()
                .map(|d| {
                    let p = apply(&rot, [d[0], d[1], d[2]]);
                    (
                        [0, 1, 2].map(|i| p[i] + origin[i]),
                        apply(&rot, [d[3], d[4], d[5]]),
                    )
                })
                .unzip();
            let theirs = peer.request(&json!({
                "op": "efield", "sphere_centre_m": centre_m, "dipoles_m": placed,
                "moments": moments, "didt": didt, "points_m": targets_m,
            }));
            let theirs = theirs["E_V_per_m"].as_array().unwrap();
            for (o, t) in ours.iter().zip(theirs) {
                let e = |v: &Value| [0, 1, 2].map(|i| v[i].as_f64().unwrap());
                let (eo, et) = (e(&o["E_V_per_m"]), e(t));
                let rel = norm([0, 1, 2].map(|i| eo[i] - et[i])) / norm(et);
                assert!(
                    norm(et) > 1.0,
                    "{name}: a field of {} V/m tests nothing",
                    norm(et)
                );
                worst = worst.max(rel);
                compared += 1;
            }
        }
        eprintln!(
            "{name}: {compared} targets and 20 poses, largest relative difference from MNE {worst:.2e}"
        );
        assert_eq!(compared, 1000);
        assert!(worst < 1e-9, "{name}: {worst:e}");
    }
}

#[test]
fn mocomp_efield_refuses_what_it_cannot_compute_by_name() {
    let coils = workspace_root().join("crates/mocomp-efield/tests/data/coils");
    let fig8 = coils.join("Magstim_70mm_Fig8.ccd").display().to_string();
    let d70 = coils.join("MagStim_D70.ccd").display().to_string();
    // The coil over the top of a 85 mm sphere, +z down (matsimnibs, mm).
    let pose = "1,0,0,0,0,-1,0,0,0,0,-1,90,0,0,0,1";
    let sphere = "0,0,0,85";
    let cases: [(&[&str], &str); 5] = [
        (
            &["--coil", &fig8, "--at", "0,0,70"],
            "no dIdtmax in its header: give --didt",
        ),
        (
            &["--coil", &d70, "--at", "0,0,86"],
            "beyond its radius of 85.0 mm",
        ),
        (&["--coil", &d70], "no point: give --at"),
        (
            &["--coil", &d70, "--at", "0,0,70", "--didt", "-3"],
            "--didt -3",
        ),
        (&["--coil", &d70, "--at", "0,0,70"], "inside its radius"),
    ];
    for (k, (extra, says)) in cases.into_iter().enumerate() {
        // The last: the coil sunk 10 mm, its windings inside the sphere.
        let pose = if k == 4 {
            "1,0,0,0,0,-1,0,0,0,0,-1,80,0,0,0,1"
        } else {
            pose
        };
        let mut args = vec!["efield", "--pose", pose, "--sphere", sphere];
        args.extend_from_slice(extra);
        let out = mocomp(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{extra:?}: {err}");
        assert!(err.contains(says), "{extra:?}: {err}");
    }
    // A pose that is not a rigid transform.
    let out = mocomp(&[
        "efield",
        "--coil",
        &d70,
        "--pose",
        "2,0,0,0,0,-1,0,0,0,0,-1,90,0,0,0,1",
        "--sphere",
        sphere,
        "--at",
        "0,0,70",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("--pose"),
        "{:?}",
        out
    );
    // And one that works, in text: the field 15 mm under the scalp, ~150–200 V/m at full output.
    let out = mocomp(&[
        "efield", "--coil", &d70, "--pose", pose, "--sphere", sphere, "--at", "0,0,70",
    ]);
    assert_success(&out);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.contains("964 dipoles") && text.contains("114.73 A/µs"),
        "{text}"
    );
}

#[test]
fn mocomp_efield_fits_the_sphere_to_a_real_scalp_under_the_coil() {
    // FreeSurfer's fsaverage scalp; the D70 over F3, its face 2 mm off the scalp.
    let dir = TempDir::new("efield-config");
    let (config, points) = common::fsaverage_config(&dir, "");
    let f3 = points["F3"];
    let out_dir = f3.coords.normalize();
    let rot = mocomp_geom::nalgebra::Rotation3::rotation_between(
        &mocomp_geom::nalgebra::Vector3::z(),
        &-out_dir,
    )
    .unwrap();
    let origin = f3.coords + out_dir * 0.002;
    let mut m = [0.0; 16];
    for i in 0..3 {
        for j in 0..3 {
            m[4 * i + j] = rot[(i, j)];
        }
        m[4 * i + 3] = origin[i] * 1e3;
    }
    m[15] = 1.0;
    let pose = m.map(|v| v.to_string()).join(",");
    let target = f3.coords - out_dir * 0.015;
    let at = format!("{},{},{}", target.x * 1e3, target.y * 1e3, target.z * 1e3);
    let coil = workspace_root()
        .join("crates/mocomp-efield/tests/data/coils/MagStim_D70.ccd")
        .display()
        .to_string();
    let run = |head: &[&str]| {
        let mut args = vec![
            "efield", "--coil", &coil, "--pose", &pose, "--at", &at, "--json",
        ];
        args.extend_from_slice(head);
        let out = mocomp(&args);
        assert_success(&out);
        serde_json::from_slice::<Value>(&out.stdout).unwrap()
    };
    let fitted = run(&["--config", &config]);
    let s = &fitted["sphere"];
    assert_eq!(s["from"], "scalp");
    let sm: Vec<f64> = (0..4)
        .map(|k| s["sphere_mm"][k].as_f64().unwrap())
        .collect();
    // A head's curvature over F3: a sphere of a head's size, centred inside it, fitting the
    // patch to a millimetre or two.
    assert!(sm[3] > 60.0 && sm[3] < 130.0, "{s}");
    assert!(norm([sm[0], sm[1], sm[2]]) < 60.0, "{s}");
    assert!(s["rms_mm"].as_f64().unwrap() < 1.5, "{s}");
    let e = |v: &Value| [0, 1, 2].map(|i| v["points"][0]["E_V_per_m"][i].as_f64().unwrap());
    let ef = e(&fitted);
    // At full output, 15 mm under the scalp: the D70's ~100–200 V/m.
    eprintln!("fsaverage over F3: sphere {s}, E 15 mm under the scalp {ef:?} V/m");
    assert!(norm(ef) > 80.0 && norm(ef) < 250.0, "{ef:?}");
    // The same sphere given: the same field.
    let given = run(&[
        "--sphere",
        &sm.iter()
            .map(|v| v.to_string())
            .collect::<Vec<_>>()
            .join(","),
    ]);
    assert_eq!(given["sphere"]["from"], "given");
    let eg = e(&given);
    assert!(
        norm([0, 1, 2].map(|i| ef[i] - eg[i])) <= 1e-12 * norm(ef),
        "{ef:?} {eg:?}"
    );
}
