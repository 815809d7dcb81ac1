//! A session's pulses as a NIBS-BIDS dataset: the BIDS extension proposal for non-invasive brain
//! stimulation (BEP037), as its draft's v5+ layout has it (`nigelrogasch/nibs-bids`,
//! `nibs-bids-v5+/`): a `nibs` datatype per session, `stimsys-tms`, one row per pulse in
//! `*_nibs.tsv` (with its `Timestamp`), the coil's pose at each in `*_markers.tsv` (`coil_*`,
//! `normal_*`, `direction_*`), the coordinate system in `*_coordsystem.json`. Around it the BIDS
//! core: `dataset_description.json`, `README`, `participants.tsv`, the session's `scans.tsv` and
//! the T1 the poses are in (`anat/*_T1w`), which the BIDS validator checks; `.bidsignore` keeps
//! the draft's `nibs/` from it, since no released validator knows it yet.
//!
//! Text only (the files' relative paths and contents); the caller writes them and copies the T1.

use mocomp_session::{Pulse, iso8601, matsimnibs};
use serde_json::json;

/// What the dataset is made from.
#[derive(Debug, Clone)]
pub struct BidsSession<'a> {
    /// The subject's label (letters and digits).
    pub subject: &'a str,
    /// The session's label.
    pub session: &'a str,
    /// The task's label.
    pub task: &'a str,
    /// The pulses, in the log's order.
    pub pulses: &'a [Pulse],
    /// The T1's extension (`nii` or `nii.gz`) when the dataset has it.
    pub t1: Option<&'a str>,
    /// The image's landmarks, RAS mm, by name.
    pub landmarks: Vec<(String, [f64; 3])>,
    /// The registration's fiducial error (RMS) and each landmark's, mm, when registered.
    pub registration: Option<(f64, Vec<(String, f64)>)>,
    /// The coil's diameter seen from the head, mm.
    pub coil_diameter_mm: f64,
    /// mocomp's version.
    pub version: &'a str,
}

/// One file of the dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct BidsFile {
    /// Its path in the dataset, `/`-separated.
    pub path: String,
    /// Its text.
    pub text: String,
}

/// A BIDS label must be letters and digits only; `option` names where it came from.
pub fn check_label(option: &str, label: &str) -> Result<(), String> {
    if !label.is_empty() && label.chars().all(|c| c.is_ascii_alphanumeric()) {
        Ok(())
    } else {
        Err(format!(
            "{option} {label:?}: a BIDS label is letters and digits only (e.g. 01)"
        ))
    }
}

/// The columns of `*_nibs.tsv`: the draft's, then mocomp's own (described in its sidecar).
pub const NIBS_COLUMNS: [&str; 17] = [
    "CoilDriver",
    "CoilID",
    "StimulusMode",
    "MarkerID",
    "StimStepCount",
    "FirstPulseAmplitude",
    "StimValidation",
    "Timestamp",
    "TargetName",
    "PositionError",
    "AngleError",
    "ScalpDistance",
    "GateReason",
    "StimulatorTimestamp",
    "LoopTime",
    "ElectricFieldTarget",
    "ElectricFieldTargetPercent",
];

/// The columns of `*_markers.tsv` (the draft's names).
pub const MARKER_COLUMNS: [&str; 12] = [
    "MarkerID",
    "coil_x",
    "coil_y",
    "coil_z",
    "normal_x",
    "normal_y",
    "normal_z",
    "direction_x",
    "direction_y",
    "direction_z",
    "Matrix_4x4",
    "Timestamp",
];

/// A TSV cell: no tab or line break inside (TSV has no quoting), `n/a` for nothing.
fn cell(s: &str) -> String {
    let s: String = s
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect();
    if s.trim().is_empty() { "n/a".into() } else { s }
}

fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "n/a".into()
    }
}

fn time(v: Option<f64>) -> String {
    v.map(iso8601)
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "n/a".into())
}

fn tsv(columns: &[&str], rows: &[Vec<String>]) -> String {
    let mut out = columns.join("\t");
    out.push('\n');
    for r in rows {
        out.push_str(&r.join("\t"));
        out.push('\n');
    }
    out
}

fn pretty(v: &serde_json::Value) -> String {
    let mut s = serde_json::to_string_pretty(v).unwrap_or_default();
    s.push('\n');
    s
}

/// Each pulse's marker: `marker<t>.<k>`, the k-th pulse with a coil pose on the t-th target to
/// be stimulated (the draft's form); `None` for a pulse without one.
pub fn marker_ids(pulses: &[Pulse]) -> Vec<Option<String>> {
    let mut targets: Vec<&str> = Vec::new();
    let mut counts: Vec<usize> = Vec::new();
    pulses
        .iter()
        .map(|p| {
            p.image_from_coil?;
            let t = match targets.iter().position(|t| *t == p.target) {
                Some(t) => t,
                None => {
                    targets.push(&p.target);
                    counts.push(0);
                    targets.len() - 1
                }
            };
            counts[t] += 1;
            Some(format!("marker{}.{}", t + 1, counts[t]))
        })
        .collect()
}

/// The dataset's files.
pub fn dataset(s: &BidsSession<'_>) -> Vec<BidsFile> {
    let prefix = format!("sub-{}_ses-{}", s.subject, s.session);
    let dir = format!("sub-{}/ses-{}", s.subject, s.session);
    let stem = format!("{dir}/nibs/{prefix}_stimsys-tms_task-{}", s.task);
    let t1 = s.t1.map(|ext| format!("anat/{prefix}_T1w.{ext}"));
    let ids = marker_ids(s.pulses);
    let mut files = top_files(s, &prefix, &dir, t1.as_deref());
    let rows = pulse_rows(s, &ids);
    files.push(BidsFile {
        path: format!("{stem}_nibs.tsv"),
        text: tsv(&NIBS_COLUMNS, &rows),
    });
    files.push(BidsFile {
        path: format!("{stem}_nibs.json"),
        text: pretty(&nibs_sidecar(s)),
    });
    let markers = marker_rows(s, &ids);
    files.push(BidsFile {
        path: format!("{stem}_markers.tsv"),
        text: tsv(&MARKER_COLUMNS, &markers),
    });
    files.push(BidsFile {
        path: format!("{stem}_markers.json"),
        text: pretty(&markers_sidecar()),
    });
    files.push(BidsFile {
        path: format!("{dir}/nibs/{prefix}_stimsys-tms_coordsystem.json"),
        text: pretty(&coordsystem(s, t1.as_deref())),
    });
    files
}

/// The dataset's description, README, `.bidsignore`, participants and the session's scans.
fn top_files(s: &BidsSession<'_>, prefix: &str, dir: &str, t1: Option<&str>) -> Vec<BidsFile> {
    vec![
        BidsFile {
            path: "dataset_description.json".into(),
            text: pretty(&json!({
                "Name": "mocomp TMS session",
                "BIDSVersion": "1.10.0",
                "DatasetType": "raw",
                "GeneratedBy": [{
                    "Name": "mocomp",
                    "Version": s.version,
                    "Description": "robotic TMS coil holder compensating head motion; \
                                    every pulse recorded with the coil's pose"
                }]
            })),
        },
        BidsFile {
            path: "README".into(),
            text: format!(
                "# mocomp TMS session\n\n\
                 A TMS session held by mocomp, a robot that keeps the coil on its target while \
                 the head moves. Every stimulator pulse is a row of `nibs/*_nibs.tsv` (its UTC \
                 time, target, the stimulator's output, whether the on-target gate was open, \
                 the coil's position and angle error and its distance to the scalp), and the \
                 coil's measured pose at it a row of `nibs/*_markers.tsv`, in the coordinates of \
                 the T1 in `anat/` (RAS, mm; SimNIBS's coil axes: normal into the head, \
                 direction pointing away from the handle).\n\n\
                 The `nibs` datatype follows the draft of BIDS extension proposal BEP037 \
                 (https://github.com/nigelrogasch/nibs-bids, its v5+ layout); no released \
                 bids-validator knows it yet, so `.bidsignore` keeps it from the validator, \
                 which checks the rest.\n\n\
                 Written by mocomp {} from {} pulses.\n",
                s.version,
                s.pulses.len()
            ),
        },
        BidsFile {
            path: ".bidsignore".into(),
            text: "# The NIBS datatype (BEP037 draft) is not in the validator yet.\n**/nibs/\n"
                .into(),
        },
        BidsFile {
            path: "participants.tsv".into(),
            text: tsv(&["participant_id"], &[vec![format!("sub-{}", s.subject)]]),
        },
        BidsFile {
            // The session's scans BIDS core knows: the T1, when the dataset has it.
            path: format!("{dir}/{prefix}_scans.tsv"),
            text: tsv(
                &["filename", "acq_time"],
                &t1.iter()
                    .map(|f| vec![f.to_string(), "n/a".into()])
                    .collect::<Vec<_>>(),
            ),
        },
    ]
}

/// A row of `_nibs.tsv` per pulse, in [`NIBS_COLUMNS`]' order.
fn pulse_rows(s: &BidsSession<'_>, ids: &[Option<String>]) -> Vec<Vec<String>> {
    s.pulses
        .iter()
        .zip(ids)
        .enumerate()
        .map(|(k, (p, id))| {
            vec![
                "robot".into(),
                "coil_1".into(),
                "single".into(),
                id.clone().unwrap_or_else(|| "n/a".into()),
                (k + 1).to_string(),
                p.output_pct.map_or_else(|| "n/a".into(), |v| num(v, 1)),
                if p.gate_open { "OK" } else { "OffTarget" }.into(),
                time(p.utc_unix_s),
                cell(&p.target),
                num(p.position_error_m * 1e3, 3),
                num(p.angle_error_rad.to_degrees(), 3),
                num(p.scalp_distance_m * 1e3, 3),
                cell(&p.why_shut),
                time(p.stimulator_unix_s),
                num(p.t_s, 4),
                num(p.dose_v_per_m, 3),
                num(p.dose_pct, 2),
            ]
        })
        .collect()
}

/// A row of `_markers.tsv` per pulse with the coil's pose on the image, in [`MARKER_COLUMNS`]'
/// order.
fn marker_rows(s: &BidsSession<'_>, ids: &[Option<String>]) -> Vec<Vec<String>> {
    s.pulses
        .iter()
        .zip(ids)
        .filter_map(|(p, id)| {
            let (pose, id) = (p.image_from_coil?, id.clone()?);
            let m = matsimnibs(&pose);
            // matsimnibs' columns: x, y (direction: away from the handle), z (normal: into the
            // head), then the centre (mm).
            let col = |c: usize, digits: usize| (0..3).map(move |r| num(m[r * 4 + c], digits));
            let mut row = vec![id];
            row.extend(col(3, 3));
            row.extend(col(2, 6));
            row.extend(col(1, 6));
            row.push(
                m.iter()
                    .map(|v| format!("{v:.6}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            );
            row.push(time(p.utc_unix_s));
            Some(row)
        })
        .collect()
}

fn described(text: &str) -> serde_json::Value {
    json!({ "Description": text })
}

fn with_units(text: &str, units: &str) -> serde_json::Value {
    json!({ "Description": text, "Units": units })
}

fn nibs_sidecar(s: &BidsSession<'_>) -> serde_json::Value {
    json!({
        "TaskName": s.task,
        "TaskDescription": "TMS pulses with the coil held on its target by mocomp's robot",
        "SoftwareVersion": format!("mocomp {}", s.version),
        "TrackingSystemName": "mocomp",
        "CoilSet": [{
            "CoilID": "coil_1",
            "CoilDiameter": {
                "Value": s.coil_diameter_mm,
                "Units": "mm",
                "Description": "The coil's diameter seen from the head (mocomp's collision model)."
            }
        }],
        "CoilDriver": {
            "Description": "Control method for the coil (manual, fixed, cobot, robot).",
            "Levels": { "robot": "Coil is dynamically positioned via a robotic system" }
        },
        "CoilID": described("Coil identifier, described in CoilSet."),
        "StimulusMode": {
            "Description": "Type of stimulus.",
            "Levels": { "single": "One pulse per trigger" }
        },
        "MarkerID": described("The coil's pose at this pulse in *_markers.tsv (n/a: the head was not tracked at the pulse)."),
        "StimStepCount": described("The pulse's number in the session, from 1."),
        "FirstPulseAmplitude": with_units("The stimulator's output (n/a: not known).", "%"),
        "StimValidation": {
            "Description": "Whether the on-target gate allowed the pulse.",
            "Levels": {
                "OK": "The gate was open: the coil on target within its tolerances for the dwell time",
                "OffTarget": "The gate was shut (GateReason says why): the pulse came all the same"
            }
        },
        "Timestamp": described("The pulse's time, ISO 8601, UTC (mocomp's clock)."),
        "TargetName": described("The session's target selected at the pulse."),
        "PositionError": with_units("The measured coil's distance from the target's coil pose.", "mm"),
        "AngleError": with_units("The angle between the measured coil's and the target's axes.", "deg"),
        "ScalpDistance": with_units("The coil centre's distance to the scalp (negative inside).", "mm"),
        "GateReason": described("Why the gate was shut (n/a: open)."),
        "StimulatorTimestamp": described("The stimulator's own time of the pulse, ISO 8601, when it gave one."),
        "LoopTime": with_units("The pulse's time on mocomp's loop clock.", "s"),
        "ElectricFieldTarget": with_units("The dose: the electric field the measured coil induced at the target's brain point, along the field its planned pose gives there (the coil's SimNIBS dipole model in the sphere fitted to the scalp under it; n/a: no coil model).", "V/m"),
        "ElectricFieldTargetPercent": with_units("ElectricFieldTarget as a percentage of the dose the target's planned coil pose gives.", "%")
    })
}

fn markers_sidecar() -> serde_json::Value {
    let axis = |what: &str, c: &str| format!("{c} component of the coil's {what} (unit vector).");
    let mut v = json!({
        "MarkerID": described("Unique identifier for each marker: marker<target>.<pulse>."),
        "Matrix_4x4": described("The coil's pose as SimNIBS's matsimnibs: 16 numbers, row by row, translation in mm."),
        "Timestamp": described("The pulse's time, ISO 8601, UTC.")
    });
    for c in ["x", "y", "z"] {
        v[format!("coil_{c}")] = with_units(
            &format!("{} coordinate of the coil's centre.", c.to_uppercase()),
            "mm",
        );
        v[format!("normal_{c}")] = described(&axis(
            "normal (its z axis, pointing into the head)",
            &c.to_uppercase(),
        ));
        v[format!("direction_{c}")] = described(&axis(
            "direction (its y axis, pointing away from the handle)",
            &c.to_uppercase(),
        ));
    }
    v
}

fn coordsystem(s: &BidsSession<'_>, t1: Option<&str>) -> serde_json::Value {
    let mut v = json!({
        "ImageData": if t1.is_some() { "NIFTI" } else { "n/a" },
        "AnatomicalLandmarkCoordinateSystem": "Individual",
        "AnatomicalLandmarkCoordinateSystemUnits": "mm",
        "AnatomicalLandmarkCoordinateSystemDescription": if t1.is_some() {
            "RAS of the T1 in anat/ (its scanner frame, mm): the frame the session's targets \
             and the coil's poses are in"
        } else {
            "The session's image frame (mm): the head marker's frame through the configured \
             head_from_image; the session had no T1"
        },
        "AnatomicalLandmarkCoordinates": s.landmarks.iter()
            .map(|(n, p)| (n.clone(), json!(p)))
            .collect::<serde_json::Map<_, _>>(),
    });
    if let Some(f) = t1 {
        v["IntendedFor"] = json!(format!("bids::sub-{}/ses-{}/{f}", s.subject, s.session));
    }
    if let Some((fre, each)) = &s.registration {
        let mut d = serde_json::Map::new();
        d.insert("RMS".into(), json!(fre));
        for (n, e) in each {
            d.insert(n.clone(), json!(e));
        }
        v["RmsDeviation"] = serde_json::Value::Object(d);
        v["RmsDeviationUnits"] = json!("mm");
        v["RmsDeviationDescription"] =
            json!("The registration's fiducial error: RMS and each landmark's");
    }
    v
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Isometry3, Vector3};

    fn pulse(t: f64, target: &str, pose: bool) -> Pulse {
        Pulse {
            t_s: t,
            utc_unix_s: Some(1_796_000_000.0 + t),
            stimulator_unix_s: None,
            target: target.into(),
            position_error_m: 0.0008,
            angle_error_rad: 0.01,
            scalp_distance_m: 0.004,
            output_pct: Some(62.0),
            head_speed: (0.0, 0.0),
            gate_open: pose,
            why_shut: if pose {
                String::new()
            } else {
                "no head estimate".into()
            },
            image_from_coil: pose.then(|| {
                Isometry3::new(
                    Vector3::new(-0.04, 0.01, 0.09),
                    Vector3::y() * std::f64::consts::PI,
                )
            }),
            dose_v_per_m: if pose { 131.5 } else { f64::NAN },
            dose_pct: if pose { 98.25 } else { f64::NAN },
        }
    }

    fn session(pulses: &[Pulse]) -> BidsSession<'_> {
        BidsSession {
            subject: "01",
            session: "01",
            task: "tms",
            pulses,
            t1: Some("nii"),
            landmarks: vec![("nasion".into(), [0.0, 85.0, -30.0])],
            registration: Some((1.2, vec![("nasion".into(), 0.9)])),
            coil_diameter_mm: 80.0,
            version: "0.1.0",
        }
    }

    fn table(text: &str) -> (Vec<String>, Vec<Vec<String>>) {
        let mut lines = text.lines();
        let head = lines
            .next()
            .unwrap()
            .split('\t')
            .map(String::from)
            .collect();
        let rows = lines
            .map(|l| l.split('\t').map(String::from).collect())
            .collect();
        (head, rows)
    }

    #[test]
    fn every_pulse_is_a_row_and_each_pose_a_marker_with_the_drafts_columns() {
        let pulses = [
            pulse(1.0, "C3", true),
            pulse(1.2, "C3", false),
            pulse(1.4, "C4\ttab", true),
            pulse(1.6, "C3", true),
        ];
        let files = dataset(&session(&pulses));
        let get = |end: &str| {
            files
                .iter()
                .find(|f| f.path.ends_with(end))
                .unwrap_or_else(|| panic!("{end}: {files:?}"))
        };
        let nibs = get("_nibs.tsv");
        assert_eq!(
            nibs.path,
            "sub-01/ses-01/nibs/sub-01_ses-01_stimsys-tms_task-tms_nibs.tsv"
        );
        let (head, rows) = table(&nibs.text);
        assert_eq!(head, NIBS_COLUMNS);
        assert_eq!(rows.len(), 4);
        for r in &rows {
            assert_eq!(r.len(), NIBS_COLUMNS.len(), "{r:?}");
        }
        let col = |name: &str| head.iter().position(|h| h == name).unwrap();
        assert_eq!(rows[0][col("MarkerID")], "marker1.1");
        assert_eq!(rows[1][col("MarkerID")], "n/a");
        assert_eq!(rows[1][col("StimValidation")], "OffTarget");
        assert_eq!(rows[1][col("GateReason")], "no head estimate");
        assert_eq!(rows[2][col("MarkerID")], "marker2.1");
        assert_eq!(rows[2][col("TargetName")], "C4 tab");
        assert_eq!(rows[3][col("MarkerID")], "marker1.2");
        assert_eq!(rows[3][col("StimStepCount")], "4");
        assert_eq!(rows[0][col("Timestamp")], "2026-11-30T00:53:21Z");
        assert_eq!(rows[0][col("FirstPulseAmplitude")], "62.0");
        assert_eq!(rows[0][col("PositionError")], "0.800");
        assert_eq!(rows[0][col("ElectricFieldTarget")], "131.500");
        assert_eq!(rows[0][col("ElectricFieldTargetPercent")], "98.25");
        assert_eq!(rows[1][col("ElectricFieldTarget")], "n/a");
        // Markers: one per pulse with a pose, the coil turned half a turn about y: its normal
        // (z) is -z, its direction (y) +y, its centre in mm.
        let (head, markers) = table(&get("_markers.tsv").text);
        assert_eq!(head, MARKER_COLUMNS);
        assert_eq!(markers.len(), 3);
        let m = &markers[0];
        let at = |name: &str| m[head.iter().position(|h| h == name).unwrap()].clone();
        assert_eq!(at("MarkerID"), "marker1.1");
        assert_eq!(
            (at("coil_x"), at("coil_y"), at("coil_z")),
            ("-40.000".into(), "10.000".into(), "90.000".into())
        );
        assert_eq!(at("normal_z"), "-1.000000");
        assert_eq!(at("direction_y"), "1.000000");
        assert_eq!(at("Matrix_4x4").split(' ').count(), 16);
        // Every column is described in its sidecar; the coordinate system names the T1.
        for (tsv, json) in [
            ("_nibs.tsv", "_nibs.json"),
            ("_markers.tsv", "_markers.json"),
        ] {
            let (head, _) = table(&get(tsv).text);
            let side: serde_json::Value = serde_json::from_str(&get(json).text).unwrap();
            for h in head {
                assert!(side.get(&h).is_some(), "{json} does not describe {h}");
            }
        }
        let cs: serde_json::Value = serde_json::from_str(&get("_coordsystem.json").text).unwrap();
        assert_eq!(
            cs["IntendedFor"],
            "bids::sub-01/ses-01/anat/sub-01_ses-01_T1w.nii"
        );
        assert_eq!(cs["RmsDeviation"]["RMS"], 1.2);
        let (_, scans) = table(&get("_scans.tsv").text);
        assert_eq!(scans, [["anat/sub-01_ses-01_T1w.nii", "n/a"]]);
    }

    #[test]
    fn a_label_is_letters_and_digits() {
        assert!(check_label("--subject", "01").is_ok());
        for bad in ["", "0-1", "a b", "sub_1", "é"] {
            let e = check_label("--subject", bad).unwrap_err();
            assert!(e.starts_with("--subject"), "{e}");
        }
    }
}
