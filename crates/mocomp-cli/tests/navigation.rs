#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! Targets from the image on a real head: FreeSurfer's fsaverage scalp (written by MNE's peer,
//! required) as `[head] mesh`, its fiducials and MNE's inion (Iz) as `[head.landmarks]`, the
//! image placed in the head marker's frame by a `head_from_image` that is not the identity.
//! `mocomp head eeg` against MNE's own montage; `mocomp targets add` by EEG position, image point
//! and MNI coordinate through an affine; bad input refused by name.

mod common;
use common::{assert_success, fsaverage_config, mocomp, pose_json, pose_toml, pose6};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_testkit::TempDir;
use serde_json::Value;

/// head_from_image of the configuration: the image's RAS turned and moved in the marker's frame.
const HEAD_FROM_IMAGE: [f64; 6] = [0.01, -0.02, 0.03, 0.1, -0.2, 0.3];

fn setup(dir: &TempDir) -> String {
    fsaverage_config(dir, &format!("head_from_image = {HEAD_FROM_IMAGE:?}\n")).0
}

fn json(out: &std::process::Output) -> Value {
    assert_success(out);
    serde_json::from_slice(&out.stdout).unwrap()
}

fn point(v: &Value) -> Point3<f64> {
    Point3::new(
        v[0].as_f64().unwrap(),
        v[1].as_f64().unwrap(),
        v[2].as_f64().unwrap(),
    )
}

fn head_from_image() -> Isometry3<f64> {
    pose6(&HEAD_FROM_IMAGE)
}

fn targets(file: &str) -> Vec<Value> {
    let out = mocomp(&["targets", "--file", file, "list", "--json"]);
    assert_success(&out);
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn eeg_positions_and_targets_from_the_image_land_on_the_scalp_in_the_marker_s_frame() {
    let dir = TempDir::new("nav-cli");
    let config = setup(&dir);
    let all = json(&mocomp(&["head", "eeg", "--config", &config, "--json"]));
    assert_eq!(all.as_object().unwrap().len(), 21);
    let (_, mne) = mocomp_testkit::anatomy::fsaverage_points("fsaverage_1020");
    for name in ["F3", "C3", "Cz"] {
        let ours = point(&all[name]);
        let theirs = mne[name] * 1e3;
        let d = (ours - theirs).norm();
        eprintln!("{name}: ours {ours}, MNE's {theirs}: {d:.1} mm apart");
        assert!(d < 8.0, "{name}: {d:.1} mm from MNE's");
    }
    let ten_ten = json(&mocomp(&[
        "head", "eeg", "--config", &config, "--system", "10-10", "--json",
    ]));
    assert_eq!(ten_ten.as_object().unwrap().len(), 61);
    assert_eq!(ten_ten["F3"], all["F3"]);

    // F3 as a target: the coil over it, 4 mm off, its axis into the head, in the marker's frame.
    let file = dir.path("targets.toml");
    let out = mocomp(&[
        "targets", "--file", &file, "add", "dlpfc", "--config", &config, "--eeg", "f3",
    ]);
    assert_success(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    eprintln!("{said}");
    assert!(said.contains("eeg F3"), "{said}");
    // An image point 20 mm below C3, handle turned 45°; an MNI point through an affine that
    // moves it onto the same place.
    let c3 = point(&all["C3"]);
    let deep = c3 + (Point3::origin() - c3).normalize() * 20.0;
    let deep_arg = format!("{},{},{}", deep.x, deep.y, deep.z);
    let out = mocomp(&[
        "targets",
        "--file",
        &file,
        "add",
        "m1",
        "--config",
        &config,
        "--image",
        &deep_arg,
        "--handle-turn-deg",
        "45",
    ]);
    assert_success(&out);
    let affine = dir.path("image_from_mni.txt");
    std::fs::write(
        &affine,
        "# image_from_mni, mm\n1 0 0 5\n0 1 0 -3\n0 0 1 2\n0 0 0 1\n",
    )
    .unwrap();
    let mni = format!("{},{},{}", deep.x - 5.0, deep.y + 3.0, deep.z - 2.0);
    let out = mocomp(&[
        "targets",
        "--file",
        &file,
        "add",
        "m1-mni",
        "--config",
        &config,
        "--mni",
        &mni,
        "--mni-affine",
        &affine,
        "--handle-turn-deg",
        "45",
    ]);
    assert_success(&out);
    let list = targets(&file);
    assert_eq!(list.len(), 3);
    let pose = |name: &str| head_from_coil(&list, name);
    let image_from_head = head_from_image().inverse();
    let f3 = image_from_head * pose("dlpfc");
    let f3_point = point(&all["F3"]) / 1e3;
    let axis = f3.rotation * Vector3::z();
    let centre = Point3::from(f3.translation.vector);
    // The face's centre 4 mm out from F3 along the outward normal, so F3 is 4 mm ahead on +z.
    let ahead = centre + axis * 0.004;
    assert!(
        (ahead - f3_point).norm() < 0.5e-3,
        "F3's coil is off: {ahead} against {f3_point}"
    );
    assert!(
        (f3_point - Point3::origin()).dot(&axis) < 0.0,
        "the axis points out of the head"
    );
    let m1 = pose("m1");
    let m1_mni = pose("m1-mni");
    assert!((m1.translation.vector - m1_mni.translation.vector).norm() < 1e-6);
    assert!(m1.rotation.angle_to(&m1_mni.rotation) < 1e-6);
    let m1_image = image_from_head * m1;
    assert!(
        ((m1_image.translation.vector - deep.coords / 1e3).norm() - 0.024).abs() < 0.003,
        "the coil over a 20 mm deep target stands about 24 mm from it"
    );
    assert!(
        list.iter().find(|t| t["name"] == "m1-mni").unwrap()["source"]
            .as_str()
            .unwrap()
            .contains("image_from_mni.txt")
    );
}

#[test]
fn bad_targets_and_landmarks_are_refused_by_name() {
    let dir = TempDir::new("nav-cli-bad");
    let config = setup(&dir);
    let file = dir.path("targets.toml");
    let refused = |args: &[&str], says: &str| {
        let out = mocomp(args);
        let err = String::from_utf8_lossy(&out.stderr).to_string();
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(err.contains(says), "{args:?}: {err}");
        assert!(
            !std::path::Path::new(&file).exists(),
            "{args:?} wrote the file"
        );
    };
    refused(
        &[
            "targets", "--file", &file, "add", "t", "--config", &config, "--image", "0,0,200",
        ],
        "outside the scalp",
    );
    refused(
        &[
            "targets", "--file", &file, "add", "t", "--config", &config, "--eeg", "Q7",
        ],
        "not a 10-10 position",
    );
    refused(
        &["targets", "--file", &file, "add", "t", "--config", &config],
        "--image",
    );
    // Landmarks in metres where millimetres belong.
    let text = std::fs::read_to_string(&config).unwrap();
    let metres = dir.path("metres.toml");
    let inion_mm = text
        .lines()
        .find(|l| l.starts_with("Inion"))
        .unwrap()
        .to_string();
    std::fs::write(
        &metres,
        text.replace(&inion_mm, "Inion = [0.003, -0.117, -0.040]"),
    )
    .unwrap();
    refused(&["head", "eeg", "--config", &metres], "inion");
    refused(&["head", "eeg", "--config", &metres], "units (mm)");
    let missing = dir.path("missing.toml");
    std::fs::write(&missing, text.replace(&inion_mm, "")).unwrap();
    refused(&["head", "eeg", "--config", &missing], "no inion");
}

/// A target's `image_from_coil` in its file, as a 4×4 in mm.
fn image_from_coil_mm(file: &str, name: &str) -> mocomp_geom::nalgebra::Matrix4<f64> {
    let doc: toml::Value = toml::from_str(&std::fs::read_to_string(file).unwrap()).unwrap();
    let t = doc["target"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["name"].as_str() == Some(name))
        .unwrap();
    let mut m = pose_toml(&t["image_from_coil"]).to_homogeneous();
    for r in 0..3 {
        m[(r, 3)] *= 1000.0;
    }
    m
}

fn head_from_coil(list: &[Value], name: &str) -> Isometry3<f64> {
    pose_json(&list.iter().find(|t| t["name"] == name).unwrap()["head_from_coil"])
}

#[test]
fn targets_from_simnibs_localite_brainsight_and_slicer_land_where_ours_do() {
    let dir = TempDir::new("nav-import");
    let config = setup(&dir);
    let ours = dir.path("ours.toml");
    for (name, eeg) in [("f3", "F3"), ("c3", "C3")] {
        let out = mocomp(&[
            "targets", "--file", &ours, "add", name, "--config", &config, "--eeg", eeg,
        ]);
        assert_success(&out);
    }
    let m = image_from_coil_mm(&ours, "f3");
    let rows = |m: &mocomp_geom::nalgebra::Matrix4<f64>| -> String {
        (0..4)
            .map(|r| {
                (0..4)
                    .map(|c| format!("{:.9}", m[(r, c)]))
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    // Each navigator's file, written as SimNIBS's nnav.py writes (or reads) it.
    let axes = mocomp_geom::nalgebra::Matrix4::new(
        0.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    );
    let lps = mocomp_geom::nalgebra::Matrix4::from_diagonal(&mocomp_geom::nalgebra::Vector4::new(
        -1.0, -1.0, 1.0, 1.0,
    ));
    let matrix4d = |m: &mocomp_geom::nalgebra::Matrix4<f64>| {
        let mut s = String::from("<Matrix4D ");
        for r in 0..4 {
            for c in 0..4 {
                s += &format!("data{r}{c}=\"{:+.17}\" ", m[(r, c)]);
            }
        }
        s + "/>"
    };
    let localite = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<InstrumentMarkerList coordinateSpace=\"LPS\">\n\
         <InstrumentMarker alwaysVisible=\"false\" index=\"0\" selected=\"false\">\n\
         <Marker additionalInformation=\"\" color=\"#ff0000\" description=\"f3-localite\" set=\"true\">\n{}\n\
         </Marker></InstrumentMarker></InstrumentMarkerList>\n",
        matrix4d(&(lps * m * axes))
    );
    let b = m * mocomp_geom::nalgebra::Matrix4::from_diagonal(
        &mocomp_geom::nalgebra::Vector4::new(-1.0, 1.0, -1.0, 1.0),
    );
    let cells: Vec<String> = std::iter::once("f3-brainsight".to_string())
        .chain((0..3).map(|r| format!("{:.4}", b[(r, 3)])))
        .chain((0..3).flat_map(|c| (0..3).map(move |r| format!("{:.4}", b[(r, c)]))))
        .collect();
    let brainsight = format!(
        "# Version: 12\n# Coordinate system: NIfTI:Aligned\n# Units: millimetres, degrees, milliseconds, and microvolts\n# Encoding: UTF-8\n\
         # Target Name\tLoc. X\tLoc. Y\tLoc. Z\tm0n0\tm0n1\tm0n2\tm1n0\tm1n1\tm1n2\tm2n0\tm2n1\tm2n2\n{}\n",
        cells.join("\t")
    );
    let c3 = point(&json(&mocomp(&["head", "eeg", "--config", &config, "--json"]))["C3"]);
    let slicer = format!(
        "{{\"@schema\": \"https://raw.githubusercontent.com/slicer/slicer/main/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#\", \
         \"markups\": [{{\"type\": \"Fiducial\", \"coordinateSystem\": \"LPS\", \"coordinateUnits\": \"mm\", \
         \"controlPoints\": [{{\"id\": \"1\", \"label\": \"c3-slicer\", \"position\": [{}, {}, {}]}}]}}]}}",
        -c3.x, -c3.y, c3.z
    );
    let files = [
        (
            "simnibs",
            "f3.txt",
            format!("# f3-simnibs\n{}\n", rows(&m)),
            "f3-simnibs",
        ),
        ("localite", "InstrumentMarker.xml", localite, "f3-localite"),
        ("brainsight", "targets.txt", brainsight, "f3-brainsight"),
        ("slicer", "c3.mrk.json", slicer, "c3-slicer"),
    ];
    let imported = dir.path("imported.toml");
    for (from, name, text, _) in &files {
        let path = dir.path(name);
        std::fs::write(&path, text).unwrap();
        let out = mocomp(&[
            "targets", "--file", &imported, "import", &path, "--from", from, "--config", &config,
        ]);
        assert_success(&out);
    }
    let (a, b) = (targets(&ours), targets(&imported));
    for (_, _, _, name) in &files {
        let want = head_from_coil(&a, if name.starts_with("c3") { "c3" } else { "f3" });
        let got = head_from_coil(&b, name);
        let (d, r) = (
            (got.translation.vector - want.translation.vector).norm(),
            got.rotation.angle_to(&want.rotation),
        );
        eprintln!(
            "{name}: {:.4} mm, {:.4}° from ours",
            d * 1e3,
            r.to_degrees()
        );
        // Brainsight's four decimals.
        assert!(d < 2e-4 && r < 2e-3, "{name}: {d} m, {r} rad");
    }
    // A matsimnibs in metres where millimetres belong: the coil would sit at the image's
    // origin, deep inside the head.
    let mut metres = m;
    for r in 0..3 {
        metres[(r, 3)] /= 1000.0;
    }
    let bad = dir.path("metres.txt");
    std::fs::write(&bad, rows(&metres)).unwrap();
    let out = mocomp(&[
        "targets", "--file", &imported, "import", &bad, "--from", "simnibs", "--config", &config,
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("inside the scalp") && err.contains("mm"),
        "{err}"
    );

    // The image's landmarks from Slicer markups (LPS) instead of the table: the same 10-20.
    let text = std::fs::read_to_string(&config).unwrap();
    let table_start = text.find("[head.landmarks]").unwrap();
    let (fid, eeg) = mocomp_testkit::anatomy::fsaverage_points("fsaverage_1005");
    let point_json = |label: &str, p: &Point3<f64>| {
        format!(
            "{{\"label\": \"{label}\", \"position\": [{}, {}, {}]}}",
            -p.x * 1e3,
            -p.y * 1e3,
            p.z * 1e3
        )
    };
    let markups = format!(
        "{{\"markups\": [{{\"type\": \"Fiducial\", \"coordinateSystem\": \"LPS\", \"coordinateUnits\": \"mm\", \"controlPoints\": [{}, {}, {}, {}]}}]}}",
        point_json("Nz", &fid["nasion"]),
        point_json("Iz", &eeg["Iz"]),
        point_json("LPA", &fid["lpa"]),
        point_json("RPA", &fid["rpa"]),
    );
    std::fs::write(dir.path("fiducials.mrk.json"), markups).unwrap();
    let from_file = dir.path("from-file.toml");
    std::fs::write(
        &from_file,
        text[..table_start].replace(
            "[head]\n",
            "[head]\nlandmarks_file = \"fiducials.mrk.json\"\n",
        ),
    )
    .unwrap();
    let again = json(&mocomp(&["head", "eeg", "--config", &from_file, "--json"]));
    let table = json(&mocomp(&["head", "eeg", "--config", &config, "--json"]));
    for name in ["F3", "C3", "Cz"] {
        let d = (point(&again[name]) - point(&table[name])).norm();
        assert!(d < 1e-6, "{name}: {d} mm apart");
    }
}

#[test]
fn the_landmarks_distance_to_the_scalp_is_said_and_one_placed_off_it_is_named() {
    let dir = TempDir::new("nav-cli-landmarks");
    let config = setup(&dir);
    let said = |config: &str| {
        let out = mocomp(&["head", "eeg", "--config", config]);
        assert_success(&out);
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    let err = said(&config);
    let line = err
        .lines()
        .find_map(|l| l.strip_prefix("landmarks off the scalp (mm, + outside): "))
        .expect("the landmarks' line");
    // Each landmark by its name in the file, with a signed distance.
    let offsets: Vec<(String, f64)> = line
        .split(", ")
        .map(|e| {
            let (n, d) = e.split_once(' ').unwrap();
            (n.to_string(), d.parse().unwrap())
        })
        .collect();
    assert_eq!(offsets.len(), 4, "{line}");
    let nasion = offsets.iter().find(|(n, _)| n == "nasion").unwrap().1;
    // The nasion moved 6 mm forward, off the face: 6 mm more (the face there is nearly square
    // to the move), and named.
    let text = std::fs::read_to_string(&config).unwrap();
    let moved: String = text
        .lines()
        .map(|l| match l.strip_prefix("nasion = [") {
            Some(rest) => {
                let v: Vec<f64> = rest
                    .trim_end_matches(']')
                    .split(',')
                    .map(|x| x.trim().parse().unwrap())
                    .collect();
                format!("nasion = [{}, {}, {}]\n", v[0], v[1] + 6.0, v[2])
            }
            None => format!("{l}\n"),
        })
        .collect();
    let off = dir.path("off.toml");
    std::fs::write(&off, moved).unwrap();
    let err = said(&off);
    let warning = err
        .lines()
        .find(|l| l.starts_with("warning: "))
        .expect("a warning");
    assert!(
        warning.contains("nasion") && warning.contains("outside"),
        "{err}"
    );
    let now: f64 = err
        .lines()
        .find_map(|l| l.strip_prefix("landmarks off the scalp (mm, + outside): "))
        .unwrap()
        .split(", ")
        .find_map(|e| e.strip_prefix("nasion "))
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        now - nasion > 3.0 && now - nasion <= 6.1,
        "{nasion} → {now}"
    );
}

/// `targets add --optimize-dose` on fsaverage with SimNIBS's Magstim D70: a target 20 mm under
/// C3 with a gyral normal given; the search's map written; the target kept at the map's best,
/// which beats the coil placed over the nearest scalp; without a coil model, refused by name.
#[test]
fn a_target_placed_by_dose_keeps_the_best_place_and_turn_of_its_map() {
    let dir = TempDir::new("nav-dose");
    let config = setup(&dir);
    let model = mocomp_testkit::workspace_root()
        .join("crates/mocomp-efield/tests/data/coils/MagStim_D70.ccd");
    let file = dir.path("targets.toml");
    let add = |rest: &[&str]| {
        let mut args = vec!["targets", "--file", &file, "add", "m1", "--config", &config];
        args.extend_from_slice(rest);
        mocomp(&args)
    };
    // Without a coil model: refused, naming what is missing.
    let out = add(&["--eeg", "C3", "--optimize-dose"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("coil.model"), "{err}");
    let mut text = std::fs::read_to_string(&config).unwrap();
    text.push_str(&format!(
        "\n[coil]\nmodel = {:?}\noutput_pct = 70.0\n",
        model.display().to_string()
    ));
    std::fs::write(&config, text).unwrap();
    // 20 mm under C3 (image frame, mm), the dose along a direction across the central sulcus.
    let all = json(&mocomp(&["head", "eeg", "--config", &config, "--json"]));
    let c3 = point(&all["C3"]);
    let inward = (Point3::origin() - c3).normalize();
    let deep = c3 + inward * 20.0;
    let at = format!("{},{},{}", deep.x, deep.y, deep.z);
    let map = dir.path("map.csv");
    let out = add(&[
        "--image",
        &at,
        "--optimize-dose",
        "--dose-direction",
        "0.6,0.8,0",
        "--dose-map",
        &map,
    ]);
    assert_success(&out);
    let said = String::from_utf8_lossy(&out.stdout);
    eprintln!("{said}");
    assert!(said.contains("targeted by dose: "), "{said}");
    // The map: every place and turn; the kept target is its best row's coil centre.
    let text = std::fs::read_to_string(&map).unwrap();
    let mut rows = csv::Reader::from_reader(text.as_bytes());
    let rows: Vec<Vec<f64>> = rows
        .records()
        .map(|r| r.unwrap().iter().map(|x| x.parse().unwrap()).collect())
        .collect();
    assert!(rows.len() > 100, "{} rows", rows.len());
    let best = rows.iter().max_by(|a, b| a[6].total_cmp(&b[6])).unwrap();
    let plain = &rows[0];
    assert_eq!((plain[0], plain[1], plain[2]), (0.0, 0.0, 0.0));
    assert!(best[6] > plain[6], "{best:?} against {plain:?}");
    let kept = image_from_coil_mm(&file, "m1");
    for r in 0..3 {
        assert!(
            (kept[(r, 3)] - best[3 + r]).abs() < 0.01,
            "{kept} against {best:?}"
        );
    }
    // Within the radius of the nearest scalp point, facing into the head.
    assert!(best[0].hypot(best[1]) <= 10.0 + 1e-9, "{best:?}");
    let axis = Vector3::new(kept[(0, 2)], kept[(1, 2)], kept[(2, 2)]);
    assert!(axis.dot(&inward) > 0.8, "{axis}");
}
