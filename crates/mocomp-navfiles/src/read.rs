//! Targets and landmarks from the navigators users already have, read from their files' text
//! (no I/O here), every pose brought into SimNIBS's coil convention in the image's RAS frame
//! (+z into the head, +y pointing away from the handle; mocomp's own):
//! - **SimNIBS**: `matsimnibs` 4×4 matrices in mm as text (`numpy.savetxt`; several, each after
//!   a `# name` line); fiducials from its CSV (`Fiducial,x,y,z,name`).
//! - **Localite** TMS Navigator: `InstrumentMarkerList`/`TriggerMarker` XML, `Matrix4D` in its
//!   own coil axes (`M_simnibs = M_localite · [[0,0,1],[0,−1,0],[1,0,0]]`), in RAS or LPS as the
//!   file's `coordinateSpace` says.
//! - **Brainsight**: its `.txt` export in `NIfTI:Aligned` (the only system whose frame is the
//!   NIfTI's), each row the position and the three axes, its x and z opposite SimNIBS's.
//! - **3D Slicer** markups (`.mrk.json`): named points in RAS or LPS, mm.
//!
//! The conventions are those SimNIBS's `utils/nnav.py` implements. Units: mm in the files,
//! metres out.

use crate::FileError;
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Point3};
use mocomp_nav::Landmark;
use quick_xml::events::{BytesStart, Event};

/// A coil pose from a navigator, image frame (RAS), m.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedPose {
    /// Its name in the file (or its index).
    pub name: String,
    /// The coil in the image's frame, SimNIBS's axes.
    pub image_from_coil: Isometry3<f64>,
}

/// Which navigator wrote a file of coil poses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Navigator {
    /// SimNIBS `matsimnibs` text.
    Simnibs,
    /// Localite XML.
    Localite,
    /// Brainsight text export.
    Brainsight,
}

impl std::str::FromStr for Navigator {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "simnibs" => Ok(Self::Simnibs),
            "localite" => Ok(Self::Localite),
            "brainsight" => Ok(Self::Brainsight),
            _ => Err(format!("{s:?}: simnibs, localite or brainsight")),
        }
    }
}

impl Navigator {
    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Simnibs => "SimNIBS",
            Self::Localite => "Localite",
            Self::Brainsight => "Brainsight",
        }
    }

    /// What its file must be in to be this image's frame.
    pub fn frame_hint(self) -> &'static str {
        match self {
            Self::Simnibs => "matsimnibs in mm, in the subject space of this patient's T1",
            Self::Localite => "planned on this patient's T1, coordinateSpace as written",
            Self::Brainsight => "exported in NIfTI:Aligned from this patient's T1",
        }
    }
}

/// How far a rotation may be from orthonormal (max |RᵀR − I|) and still be taken as one (and
/// made orthonormal): Brainsight writes three or four decimals of a tracked sample that was not
/// exactly orthonormal itself; one of its own exports (SimNIBS's test data) is 2.02e-3 off. A
/// matrix that is no rotation (scaled, sheared, mirrored) is off by tenths.
const RIGID_TOLERANCE: f64 = 5e-3;

/// The coil poses of `text`, the file `file` written by `navigator`.
pub fn parse_poses(
    navigator: Navigator,
    file: &str,
    text: &str,
) -> Result<Vec<NamedPose>, FileError> {
    let poses = match navigator {
        Navigator::Simnibs => simnibs(file, text)?,
        Navigator::Localite => localite(file, text)?,
        Navigator::Brainsight => brainsight(file, text)?,
    };
    if poses.is_empty() {
        return Err(FileError(format!("{file}: no coil pose in it")));
    }
    Ok(poses)
}

fn bad(file: &str, line: usize, why: impl std::fmt::Display) -> FileError {
    FileError(format!("{file}:{line}: {why}"))
}

fn rigid(file: &str, line: usize, m: &Matrix4<f64>) -> Result<Isometry3<f64>, FileError> {
    iso_from_matrix_mm(m, RIGID_TOLERANCE).map_err(|e| {
        bad(
            file,
            line,
            format!("not a coil pose (a rotation and a translation in mm): {e}"),
        )
    })
}

fn number(file: &str, line: usize, s: &str) -> Result<f64, FileError> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| bad(file, line, format!("{s:?} is not a finite number")))
}

/// `matsimnibs` matrices: four rows of four numbers each, a `# name` line before one naming it.
fn simnibs(file: &str, text: &str) -> Result<Vec<NamedPose>, FileError> {
    let mut out = Vec::new();
    let mut name: Option<String> = None;
    let mut rows: Vec<[f64; 4]> = Vec::new();
    let mut first_line = 0;
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        let t = line.trim();
        if let Some(comment) = t.strip_prefix('#') {
            if rows.is_empty() && !comment.trim().is_empty() {
                name = Some(comment.trim().to_string());
            }
            continue;
        }
        if t.is_empty() {
            continue;
        }
        let v: Vec<&str> = t
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|s| !s.is_empty())
            .collect();
        if v.len() != 4 {
            return Err(bad(
                file,
                n,
                format!("{} numbers, a matsimnibs row has 4", v.len()),
            ));
        }
        if rows.is_empty() {
            first_line = n;
        }
        let mut row = [0.0; 4];
        for (slot, s) in row.iter_mut().zip(&v) {
            *slot = number(file, n, s)?;
        }
        rows.push(row);
        if rows.len() == 4 {
            let m = Matrix4::from_fn(|r, c| rows[r][c]);
            out.push(NamedPose {
                name: name.take().unwrap_or_else(|| out.len().to_string()),
                image_from_coil: rigid(file, first_line, &m)?,
            });
            rows.clear();
        }
    }
    if !rows.is_empty() {
        return Err(bad(
            file,
            first_line,
            format!("a matsimnibs with {} rows, not 4", rows.len()),
        ));
    }
    Ok(out)
}

/// Localite's coil axes to SimNIBS's, multiplied on the right.
pub(crate) fn localite_axes() -> Matrix4<f64> {
    Matrix4::new(
        0.0, 0.0, 1.0, 0.0, //
        0.0, -1.0, 0.0, 0.0, //
        1.0, 0.0, 0.0, 0.0, //
        0.0, 0.0, 0.0, 1.0,
    )
}

/// LPS to RAS (and back), multiplied on the left.
fn lps_ras() -> Matrix4<f64> {
    Matrix4::from_diagonal(&mocomp_geom::nalgebra::Vector4::new(-1.0, -1.0, 1.0, 1.0))
}

fn attributes(e: &BytesStart<'_>) -> std::collections::HashMap<String, String> {
    e.attributes()
        .filter_map(Result::ok)
        .filter_map(|a| {
            // Unescaped (`&amp;` is `&`), as XML means it; a broken entity drops the attribute,
            // which the caller then names as missing.
            let v = a
                .normalized_value(quick_xml::XmlVersion::Implicit1_0)
                .ok()?
                .into_owned();
            Some((a.key.as_ref().to_string(), v))
        })
        .collect()
}

/// Localite's XML: the list's `coordinateSpace`, each marker's `description` and `Matrix4D`.
fn localite(file: &str, text: &str) -> Result<Vec<NamedPose>, FileError> {
    let mut reader = quick_xml::Reader::from_str(text);
    let mut lps = None;
    let mut name: Option<String> = None;
    let mut out = Vec::new();
    // The line of a byte offset, counted only for an error (counting for every event would
    // read a 900 kB trigger file once per marker).
    let line_of = |at: u64| {
        let at = usize::try_from(at).unwrap_or(usize::MAX).min(text.len());
        1 + text.as_bytes()[..at]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
    };
    loop {
        let at = reader.buffer_position();
        let event = reader
            .read_event()
            .map_err(|e| bad(file, line_of(at), format!("not Localite XML: {e}")))?;
        let line = || line_of(at);
        let e = match &event {
            Event::Start(e) | Event::Empty(e) => e,
            Event::Eof => break,
            _ => continue,
        };
        let a = attributes(e);
        match e.name().as_ref() {
            "InstrumentMarkerList" | "TriggerMarkerList" => {
                lps = Some(
                    match a.get("coordinateSpace").map(|s| s.to_ascii_uppercase()) {
                        Some(s) if s == "RAS" => false,
                        Some(s) if s == "LPS" => true,
                        other => {
                            return Err(bad(
                                file,
                                line(),
                                format!("coordinateSpace {other:?}: RAS or LPS"),
                            ));
                        }
                    },
                );
            }
            "Marker" | "TriggerMarker" => {
                name = a.get("description").cloned();
            }
            "Matrix4D" => {
                let mut m = Matrix4::zeros();
                for r in 0..4 {
                    for c in 0..4 {
                        let key = format!("data{r}{c}");
                        let v = a
                            .get(&key)
                            .ok_or_else(|| bad(file, line(), format!("Matrix4D has no {key}")))?;
                        m[(r, c)] = number(file, line(), v)?;
                    }
                }
                // An untracked marker (the coil not seen) is written as the identity.
                if m == Matrix4::identity() {
                    continue;
                }
                let flip = lps.ok_or_else(|| {
                    bad(file, line(), "a Matrix4D outside an InstrumentMarkerList")
                })?;
                let m = if flip { lps_ras() * m } else { m } * localite_axes();
                out.push(NamedPose {
                    name: name.take().unwrap_or_else(|| out.len().to_string()),
                    image_from_coil: rigid(file, line(), &m)?,
                });
            }
            _ => {}
        }
    }
    if lps.is_none() {
        return Err(FileError(format!(
            "{file}: no InstrumentMarkerList or TriggerMarkerList: not a Localite marker file"
        )));
    }
    Ok(out)
}

/// Brainsight's text export: `# Coordinate system:` (NIfTI:Aligned up to version 13, its
/// NIfTI:Q:Aligned or NIfTI:S:Aligned from version 14), then the `# Target Name` and `# Sample
/// Name` tables' tab-separated rows; the other tables (sessions, EMG) are not coil poses.
fn brainsight(file: &str, text: &str) -> Result<Vec<NamedPose>, FileError> {
    let mut system = None;
    let mut columns: Option<Vec<String>> = None;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        if let Some(s) = line.strip_prefix("# Coordinate system:") {
            system = Some(s.trim().to_string());
            continue;
        }
        if line.starts_with("# Target Name") || line.starts_with("# Sample Name") {
            columns = Some(
                line.trim_start_matches("# ")
                    .split('\t')
                    .map(|s| s.trim().to_string())
                    .collect(),
            );
            continue;
        }
        if line.starts_with('#') {
            if line.contains('\t') {
                // Another table's header: its rows are not coil poses.
                columns = None;
            }
            continue;
        }
        if line.trim().is_empty() {
            continue;
        }
        let Some(cols) = &columns else { continue };
        match system.as_deref() {
            Some(s)
                if ["NIfTI:Aligned", "NIfTI:Q:Aligned", "NIfTI:S:Aligned"]
                    .iter()
                    .any(|a| s.eq_ignore_ascii_case(a)) => {}
            other => {
                return Err(bad(
                    file,
                    n,
                    format!(
                        "coordinate system {other:?}: export the targets in NIfTI:Aligned \
                         (NIfTI:Q:Aligned or NIfTI:S:Aligned from Brainsight 2.5.3), the only \
                         Brainsight systems that are the NIfTI's own RAS"
                    ),
                ));
            }
        }
        let cells: Vec<&str> = line.split('\t').collect();
        let get = |name: &str| -> Result<f64, FileError> {
            let k = cols
                .iter()
                .position(|c| c == name)
                .ok_or_else(|| bad(file, n, format!("no column {name:?}")))?;
            number(file, n, cells.get(k).copied().unwrap_or(""))
        };
        let mut m = Matrix4::identity();
        for (c, axis) in ["m0", "m1", "m2"].iter().enumerate() {
            for r in 0..3 {
                m[(r, c)] = get(&format!("{axis}n{r}"))?;
            }
        }
        for (r, loc) in ["Loc. X", "Loc. Y", "Loc. Z"].iter().enumerate() {
            m[(r, 3)] = get(loc)?;
        }
        // Brainsight's coil x and z are SimNIBS's reversed.
        let flip =
            Matrix4::from_diagonal(&mocomp_geom::nalgebra::Vector4::new(-1.0, 1.0, -1.0, 1.0));
        out.push(NamedPose {
            name: cells
                .first()
                .map_or_else(|| out.len().to_string(), |s| s.to_string()),
            image_from_coil: rigid(file, n, &(m * flip))?,
        });
    }
    if system.is_none() {
        return Err(FileError(format!(
            "{file}: no \"# Coordinate system:\" line: not a Brainsight text export"
        )));
    }
    Ok(out)
}

/// The control points of a 3D Slicer markups file (`.mrk.json`), by label, RAS, m.
pub fn slicer_points(file: &str, text: &str) -> Result<Vec<Landmark>, FileError> {
    let doc: serde_json::Value =
        serde_json::from_str(text).map_err(|e| FileError(format!("{file}: not JSON: {e}")))?;
    let markups = doc["markups"].as_array().ok_or_else(|| {
        FileError(format!(
            "{file}: no \"markups\" list: not a Slicer markups file"
        ))
    })?;
    let mut out = Vec::new();
    for (k, m) in markups.iter().enumerate() {
        let system = m["coordinateSystem"].as_str().unwrap_or("LPS");
        let flip = match system {
            "LPS" => -1.0,
            "RAS" => 1.0,
            other => {
                return Err(FileError(format!(
                    "{file}: markups[{k}].coordinateSystem {other:?}: LPS or RAS"
                )));
            }
        };
        if let Some(units) = m["coordinateUnits"].as_str()
            && units != "mm"
        {
            return Err(FileError(format!(
                "{file}: markups[{k}].coordinateUnits {units:?}: mocomp reads mm"
            )));
        }
        let points = m["controlPoints"].as_array().map_or(&[][..], Vec::as_slice);
        for (j, p) in points.iter().enumerate() {
            let at = |i: usize| p["position"][i].as_f64().filter(|v| v.is_finite());
            let (Some(x), Some(y), Some(z)) = (at(0), at(1), at(2)) else {
                return Err(FileError(format!(
                    "{file}: markups[{k}].controlPoints[{j}].position is not three finite numbers"
                )));
            };
            let label = p["label"]
                .as_str()
                .map_or_else(|| format!("{k}-{j}"), str::to_string);
            out.push(Landmark::new(
                &label,
                Point3::new(flip * x, flip * y, z) / 1000.0,
            ));
        }
    }
    if out.is_empty() {
        return Err(FileError(format!("{file}: no control points in it")));
    }
    Ok(out)
}

/// The `Fiducial` rows of a SimNIBS positions CSV (`Fiducial,x,y,z,name`, mm), m.
pub fn simnibs_fiducials(file: &str, text: &str) -> Result<Vec<Landmark>, FileError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        if cells.first() != Some(&"Fiducial") {
            continue;
        }
        if cells.len() < 5 {
            return Err(bad(file, i + 1, "a Fiducial row is Fiducial,x,y,z,name"));
        }
        let p = Point3::new(
            number(file, i + 1, cells[1])?,
            number(file, i + 1, cells[2])?,
            number(file, i + 1, cells[3])?,
        );
        out.push(Landmark::new(cells[4], p / 1000.0));
    }
    if out.is_empty() {
        return Err(FileError(format!("{file}: no Fiducial rows in it")));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};

    /// A coil over the left motor cortex, SimNIBS's axes, mm.
    fn truth() -> Matrix4<f64> {
        let mut m = Isometry3::from_parts(
            Translation3::new(-38.5, -20.25, 78.0),
            UnitQuaternion::from_euler_angles(2.6, 0.4, -0.7),
        )
        .to_homogeneous();
        m[(3, 3)] = 1.0;
        m
    }

    fn close(p: &NamedPose, m: &Matrix4<f64>) {
        let mut got = p.image_from_coil.to_homogeneous();
        for r in 0..3 {
            got[(r, 3)] *= 1000.0;
        }
        assert!(
            (got - m).abs().max() < 1e-3,
            "{}: {got} against {m}",
            p.name
        );
    }

    fn rows(m: &Matrix4<f64>) -> String {
        (0..4)
            .map(|r| {
                (0..4)
                    .map(|c| format!("{:.9}", m[(r, c)]))
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    fn matrix4d(m: &Matrix4<f64>) -> String {
        let mut s = String::from("<Matrix4D ");
        for r in 0..4 {
            for c in 0..4 {
                s += &format!("data{r}{c}=\"{:+.17}\" ", m[(r, c)]);
            }
        }
        s + "/>"
    }

    #[test]
    fn a_matsimnibs_text_reads_as_the_coil_pose_and_faults_name_the_line() {
        let text = format!(
            "# M1 hotspot\n{}\n\n{}\n",
            rows(&truth()),
            rows(&Matrix4::identity())
        );
        let poses = parse_poses(Navigator::Simnibs, "m.txt", &text).unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].name, "M1 hotspot");
        assert_eq!(poses[1].name, "1");
        close(&poses[0], &truth());
        let mut scaled = truth();
        scaled[(0, 0)] *= 1.1;
        let e = parse_poses(Navigator::Simnibs, "m.txt", &rows(&scaled))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("m.txt:1") && e.contains("not a coil pose"),
            "{e}"
        );
        let e = parse_poses(Navigator::Simnibs, "m.txt", "1 0 0 0\n0 1 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("m.txt:2: 3 numbers"), "{e}");
        let e = parse_poses(Navigator::Simnibs, "m.txt", "1 0 0 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("1 rows"), "{e}");
    }

    #[test]
    fn localite_markers_in_ras_and_lps_read_as_simnibs_poses_and_untracked_ones_are_skipped() {
        // Localite's own axes: M_loc = M_sim · axes; in LPS the rows flip too.
        let loc = truth() * localite_axes();
        for (space, m) in [("RAS", loc), ("LPS", lps_ras() * loc)] {
            let xml = format!(
                "<?xml version=\"1.0\"?>\n<InstrumentMarkerList coordinateSpace=\"{space}\">\n\
                 <InstrumentMarker><Marker description=\"hot\">{}</Marker></InstrumentMarker>\n\
                 <InstrumentMarker><Marker description=\"lost\">{}</Marker></InstrumentMarker>\n\
                 </InstrumentMarkerList>\n",
                matrix4d(&m),
                matrix4d(&Matrix4::identity())
            );
            let poses = parse_poses(Navigator::Localite, "im.xml", &xml).unwrap();
            assert_eq!(poses.len(), 1, "{space}");
            assert_eq!(poses[0].name, "hot");
            close(&poses[0], &truth());
        }
        let e = parse_poses(
            Navigator::Localite,
            "im.xml",
            "<InstrumentMarkerList coordinateSpace=\"XYZ\"></InstrumentMarkerList>",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("coordinateSpace"), "{e}");
    }

    #[test]
    fn brainsight_targets_in_nifti_aligned_read_and_other_systems_are_refused() {
        let b = truth()
            * Matrix4::from_diagonal(&mocomp_geom::nalgebra::Vector4::new(-1.0, 1.0, -1.0, 1.0));
        let row: Vec<String> = std::iter::once("C3 hot".to_string())
            .chain((0..3).map(|r| format!("{:.4}", b[(r, 3)])))
            .chain((0..3).flat_map(|c| (0..3).map(move |r| format!("{:.4}", b[(r, c)]))))
            .collect();
        let header = "# Version: 12\n# Coordinate system: NIfTI:Aligned\n# Encoding: UTF-8\n\
                      # Target Name\tLoc. X\tLoc. Y\tLoc. Z\tm0n0\tm0n1\tm0n2\tm1n0\tm1n1\tm1n2\tm2n0\tm2n1\tm2n2\n";
        let text = format!("{header}{}\n", row.join("\t"));
        let poses = parse_poses(Navigator::Brainsight, "bs.txt", &text).unwrap();
        assert_eq!(poses[0].name, "C3 hot");
        close(&poses[0], &truth());
        let other = text.replace("NIfTI:Aligned", "Brainsight");
        let e = parse_poses(Navigator::Brainsight, "bs.txt", &other)
            .unwrap_err()
            .to_string();
        assert!(e.contains("bs.txt:5") && e.contains("NIfTI:Aligned"), "{e}");
    }

    #[test]
    fn slicer_markups_and_simnibs_fiducials_read_as_ras_landmarks() {
        let json = r#"{"@schema": "https://raw.githubusercontent.com/slicer/slicer/main/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#",
          "markups": [{"type": "Fiducial", "coordinateSystem": "LPS", "coordinateUnits": "mm",
            "controlPoints": [{"id": "1", "label": "nasion", "position": [-1.5, -85.1, -34.8]},
                              {"id": "2", "label": "LPA", "position": [80.6, 29.1, -41.3]}]}]}"#;
        let l = slicer_points("f.mrk.json", json).unwrap();
        assert_eq!(l.len(), 2);
        assert_eq!(l[0].name, "nasion");
        assert!((l[0].point - Point3::new(0.0015, 0.0851, -0.0348)).norm() < 1e-12);
        assert!((l[1].point - Point3::new(-0.0806, -0.0291, -0.0413)).norm() < 1e-12);
        let e = slicer_points("f.mrk.json", &json.replace("\"mm\"", "\"um\""))
            .unwrap_err()
            .to_string();
        assert!(e.contains("coordinateUnits"), "{e}");
        assert!(
            slicer_points("f.mrk.json", "{}")
                .unwrap_err()
                .to_string()
                .contains("markups")
        );
        let csv = "Fiducial,1.5,85.1,-34.8,Nz\nElectrode,-49.1,52.5,39.3,F3\nFiducial,-80.6,-29.1,-41.3,LPA\n";
        let f = simnibs_fiducials("eeg.csv", csv).unwrap();
        assert_eq!(
            f.iter().map(|l| l.name.as_str()).collect::<Vec<_>>(),
            ["Nz", "LPA"]
        );
        assert!((f[0].point - Point3::new(0.0015, 0.0851, -0.0348)).norm() < 1e-12);
    }
}
