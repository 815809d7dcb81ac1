//! Calibration pairs and the pairs file (CSV).
//!
//! A pairs file has a header and one pair per line. The robot side is either the flange pose as a
//! UR pose vector, `flange_x_m, flange_y_m, flange_z_m, flange_rx, flange_ry, flange_rz` (metres,
//! rotation vector), or the joints `q1, …, q6` (radians; needs the robot model). The tracker side
//! is `marker_x_mm, marker_y_mm, marker_z_mm, marker_qw, marker_qx, marker_qy, marker_qz`
//! (millimetres and a unit quaternion, the way trackers report). Column order is free; unknown
//! columns are rejected; lines starting with `#` are comments. Every bad cell is reported with its
//! line and column.

use crate::error::{CalibError, PairRef};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::units::{m_to_mm, mm_to_m};
use mocomp_geom::{iso_from_ur_pose, iso_from_wxyz, ur_pose_from_iso, wxyz_from_iso};
use mocomp_kin::Arm;
use std::fmt::Write;

/// One calibration measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pair {
    /// The robot's flange pose (forward kinematics).
    pub base_from_flange: Isometry3<f64>,
    /// The tracker's measurement of the marker.
    pub tracker_from_marker: Isometry3<f64>,
    /// The joints the flange pose came from, when known.
    pub joints: Option<[f64; 6]>,
    /// 1-based line in the pairs file, when read from one.
    pub line: Option<usize>,
}

impl Pair {
    /// A pair from the two transforms.
    pub fn new(base_from_flange: Isometry3<f64>, tracker_from_marker: Isometry3<f64>) -> Self {
        Self {
            base_from_flange,
            tracker_from_marker,
            joints: None,
            line: None,
        }
    }

    /// How to name this pair in messages.
    pub fn reference(&self, index: usize) -> PairRef {
        PairRef {
            index,
            line: self.line,
        }
    }
}

/// Robot-side columns of a pairs file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PairsFormat {
    /// `flange_x_m … flange_rz` (UR pose vector).
    Pose,
    /// `q1 … q6` (joints, radians).
    Joints,
}

/// Column names of the flange pose.
pub const POSE_COLUMNS: [&str; 6] = [
    "flange_x_m",
    "flange_y_m",
    "flange_z_m",
    "flange_rx",
    "flange_ry",
    "flange_rz",
];
/// Column names of the joints.
pub const JOINT_COLUMNS: [&str; 6] = ["q1", "q2", "q3", "q4", "q5", "q6"];
/// Column names of the marker measurement.
pub const MARKER_COLUMNS: [&str; 7] = [
    "marker_x_mm",
    "marker_y_mm",
    "marker_z_mm",
    "marker_qw",
    "marker_qx",
    "marker_qy",
    "marker_qz",
];
/// How far a quaternion's norm may be from 1 before its row is rejected.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

fn file_error(file: &str, line: usize, column: Option<usize>, message: String) -> CalibError {
    CalibError::PairsFile {
        file: file.to_string(),
        line,
        column,
        message,
    }
}

/// Where each needed column is, by header position.
struct Layout {
    robot: [usize; 6],
    format: PairsFormat,
    marker: [usize; 7],
}

fn layout(file: &str, header: &csv::StringRecord, have_arm: bool) -> Result<Layout, CalibError> {
    let names: Vec<String> = header.iter().map(|h| h.trim().to_string()).collect();
    let find = |name: &str| names.iter().position(|n| n == name);
    // Unknown and repeated columns.
    for (i, n) in names.iter().enumerate() {
        let known = POSE_COLUMNS.contains(&n.as_str())
            || JOINT_COLUMNS.contains(&n.as_str())
            || MARKER_COLUMNS.contains(&n.as_str());
        if !known {
            return Err(file_error(
                file,
                1,
                Some(i + 1),
                format!(
                    "unknown column {n:?}; expected {} or {}, and {}",
                    POSE_COLUMNS.join(", "),
                    JOINT_COLUMNS.join(", "),
                    MARKER_COLUMNS.join(", ")
                ),
            ));
        }
        if names[..i].contains(n) {
            return Err(file_error(
                file,
                1,
                Some(i + 1),
                format!("column {n:?} appears twice"),
            ));
        }
    }
    fn collect<'a>(
        cols: &[&'a str],
        find: impl Fn(&str) -> Option<usize>,
    ) -> (Vec<usize>, Vec<&'a str>) {
        let mut found = Vec::new();
        let mut missing = Vec::new();
        for c in cols {
            match find(c) {
                Some(i) => found.push(i),
                None => missing.push(*c),
            }
        }
        (found, missing)
    }
    let (pose, pose_missing) = collect(&POSE_COLUMNS, find);
    let (joints, joints_missing) = collect(&JOINT_COLUMNS, find);
    let (marker, marker_missing) = collect(&MARKER_COLUMNS, find);
    if !marker_missing.is_empty() {
        return Err(file_error(
            file,
            1,
            None,
            format!("missing column(s) {}", marker_missing.join(", ")),
        ));
    }
    let (robot, format) = match (pose.len(), joints.len()) {
        (6, 0) => (pose, PairsFormat::Pose),
        (0, 6) => {
            if !have_arm {
                return Err(file_error(
                    file,
                    1,
                    None,
                    "joint columns q1..q6 need the robot model (--robot)".into(),
                ));
            }
            (joints, PairsFormat::Joints)
        }
        (0, 0) => {
            return Err(file_error(
                file,
                1,
                None,
                format!(
                    "no robot columns: give {} or {}",
                    POSE_COLUMNS.join(", "),
                    JOINT_COLUMNS.join(", ")
                ),
            ));
        }
        (p, j) if p > 0 && j > 0 => {
            return Err(file_error(
                file,
                1,
                None,
                "give either the flange pose columns or the joint columns, not both".into(),
            ));
        }
        (p, _) if p > 0 => {
            return Err(file_error(
                file,
                1,
                None,
                format!("missing column(s) {}", pose_missing.join(", ")),
            ));
        }
        _ => {
            return Err(file_error(
                file,
                1,
                None,
                format!("missing column(s) {}", joints_missing.join(", ")),
            ));
        }
    };
    Ok(Layout {
        robot: robot.try_into().unwrap_or([0; 6]),
        format,
        marker: marker.try_into().unwrap_or([0; 7]),
    })
}

/// Parses a pairs file. `file` names it in errors; `arm` turns joint columns into flange poses
/// (its calibration is used; its tool is not: X is relative to the flange).
pub fn parse_pairs_csv(text: &str, file: &str, arm: Option<&Arm>) -> Result<Vec<Pair>, CalibError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .from_reader(text.as_bytes());
    let header = reader
        .headers()
        .map_err(|e| file_error(file, 1, None, e.to_string()))?
        .clone();
    if header.iter().all(|h| h.trim().is_empty()) {
        return Err(file_error(file, 1, None, "empty file: no header".into()));
    }
    let lay = layout(file, &header, arm.is_some())?;
    let mut pairs = Vec::new();
    for record in reader.records() {
        let record = record.map_err(|e| {
            let line = e.position().map(|p| p.line() as usize).unwrap_or(0);
            let message = match e.kind() {
                csv::ErrorKind::UnequalLengths {
                    expected_len, len, ..
                } => {
                    format!("{len} fields, but the header has {expected_len}")
                }
                _ => e.to_string(),
            };
            file_error(file, line, None, message)
        })?;
        let line = record.position().map(|p| p.line() as usize).unwrap_or(0);
        let cell = |col: usize| -> Result<f64, CalibError> {
            let text = record.get(col).unwrap_or("");
            let name = header.get(col).unwrap_or("").trim();
            let v: f64 = text.parse().map_err(|_| {
                file_error(
                    file,
                    line,
                    Some(col + 1),
                    format!("{name}: {text:?} is not a number"),
                )
            })?;
            if !v.is_finite() {
                return Err(file_error(
                    file,
                    line,
                    Some(col + 1),
                    format!("{name}: {text:?} is not a finite number"),
                ));
            }
            Ok(v)
        };
        let mut robot = [0.0; 6];
        for (v, &col) in robot.iter_mut().zip(lay.robot.iter()) {
            *v = cell(col)?;
        }
        let mut marker = [0.0; 7];
        for (v, &col) in marker.iter_mut().zip(lay.marker.iter()) {
            *v = cell(col)?;
        }
        let (base_from_flange, joints) = match (lay.format, arm) {
            (PairsFormat::Joints, Some(arm)) => (arm.fk_flange(&robot), Some(robot)),
            _ => (
                iso_from_ur_pose(&robot)
                    .map_err(|e| file_error(file, line, None, e.to_string()))?,
                None,
            ),
        };
        let t = [mm_to_m(marker[0]), mm_to_m(marker[1]), mm_to_m(marker[2])];
        let q = [marker[3], marker[4], marker[5], marker[6]];
        let tracker_from_marker =
            iso_from_wxyz(&t, &q, QUATERNION_NORM_TOLERANCE).map_err(|e| {
                file_error(
                    file,
                    line,
                    Some(lay.marker[3] + 1),
                    format!("marker quaternion: {e}"),
                )
            })?;
        pairs.push(Pair {
            base_from_flange,
            tracker_from_marker,
            joints,
            line: Some(line),
        });
    }
    if pairs.is_empty() {
        return Err(file_error(
            file,
            1,
            None,
            "no pairs: the file has a header but no data lines".into(),
        ));
    }
    Ok(pairs)
}

/// Writes pairs as a pairs file. `Joints` needs every pair's joints.
pub fn write_pairs_csv(pairs: &[Pair], format: PairsFormat) -> Result<String, CalibError> {
    let mut out = String::new();
    let robot_cols: &[&str] = match format {
        PairsFormat::Pose => &POSE_COLUMNS,
        PairsFormat::Joints => &JOINT_COLUMNS,
    };
    let header: Vec<&str> = robot_cols
        .iter()
        .chain(MARKER_COLUMNS.iter())
        .copied()
        .collect();
    out.push_str(&header.join(","));
    out.push('\n');
    for (i, p) in pairs.iter().enumerate() {
        let robot = match format {
            PairsFormat::Pose => ur_pose_from_iso(&p.base_from_flange),
            PairsFormat::Joints => p.joints.ok_or_else(|| {
                CalibError::InvalidOption(format!("pair {} has no joints to write", i + 1))
            })?,
        };
        let (t, q) = wxyz_from_iso(&p.tracker_from_marker);
        let values = robot
            .iter()
            .copied()
            .chain(t.iter().map(|v| m_to_mm(*v)))
            .chain(q.iter().copied());
        let mut first = true;
        for v in values {
            if !first {
                out.push(',');
            }
            first = false;
            // Shortest representation that reads back to the same f64.
            write!(out, "{v:?}").ok();
        }
        out.push('\n');
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use mocomp_geom::nalgebra::{Translation3, Vector3};
    use mocomp_geom::{quat_from_rotvec, rotation_error, translation_error};
    use mocomp_kin::Model;

    fn sample_pairs() -> Vec<Pair> {
        (0..4)
            .map(|i| {
                let f = i as f64;
                let mut p = Pair::new(
                    Isometry3::from_parts(
                        Translation3::new(0.3 + 0.01 * f, -0.2, 0.4),
                        quat_from_rotvec(&Vector3::new(0.1 * f, 3.0, -0.2)),
                    ),
                    Isometry3::from_parts(
                        Translation3::new(0.1, 0.05 * f, 1.2),
                        quat_from_rotvec(&Vector3::new(-0.3, 0.2 * f, 0.1)),
                    ),
                );
                p.joints = Some([0.1 * f, -1.0, 1.2, -0.5, 1.1, 0.3]);
                p
            })
            .collect()
    }

    #[test]
    fn round_trips_pose_format() {
        let pairs = sample_pairs();
        let text = write_pairs_csv(&pairs, PairsFormat::Pose).unwrap();
        let back = parse_pairs_csv(&text, "p.csv", None).unwrap();
        assert_eq!(back.len(), 4);
        for (a, b) in pairs.iter().zip(&back) {
            assert!(translation_error(&a.base_from_flange, &b.base_from_flange) < 1e-15);
            assert!(rotation_error(&a.base_from_flange, &b.base_from_flange) < 1e-15);
            assert!(translation_error(&a.tracker_from_marker, &b.tracker_from_marker) < 1e-15);
            assert!(rotation_error(&a.tracker_from_marker, &b.tracker_from_marker) < 1e-15);
        }
        assert_eq!(back[0].line, Some(2));
        assert_eq!(back[3].line, Some(5));
    }

    #[test]
    fn joint_format_uses_the_robot() {
        let arm = Arm::new(Model::Ur3);
        let pairs = sample_pairs();
        let text = write_pairs_csv(&pairs, PairsFormat::Joints).unwrap();
        let err = parse_pairs_csv(&text, "p.csv", None).unwrap_err();
        assert!(err.to_string().contains("--robot"), "{err}");
        let back = parse_pairs_csv(&text, "p.csv", Some(&arm)).unwrap();
        let q = pairs[2].joints.unwrap();
        assert!(translation_error(&back[2].base_from_flange, &arm.fk_flange(&q)) < 1e-15);
    }

    fn err(text: &str) -> String {
        parse_pairs_csv(text, "bad.csv", None)
            .unwrap_err()
            .to_string()
    }

    const HEADER: &str = "flange_x_m,flange_y_m,flange_z_m,flange_rx,flange_ry,flange_rz,marker_x_mm,marker_y_mm,marker_z_mm,marker_qw,marker_qx,marker_qy,marker_qz";

    #[test]
    fn bad_cells_name_line_and_column() {
        let text =
            format!("{HEADER}\n0.1,0.2,0.3,0,0,0,1,2,3,1,0,0,0\n0.1,0.2,abc,0,0,0,1,2,3,1,0,0,0\n");
        let e = err(&text);
        assert!(
            e.contains("bad.csv: line 3, column 3") && e.contains("flange_z_m"),
            "{e}"
        );
        let text = format!("{HEADER}\n0.1,0.2,0.3,0,0,0,1,2,3,1,0,0,NaN\n");
        assert!(err(&text).contains("line 2, column 13"), "{}", err(&text));
        let text = format!("{HEADER}\n0.1,0.2,0.3,0,0,0,1,2,3,0.5,0,0,0\n");
        let e = err(&text);
        assert!(
            e.contains("line 2, column 10") && e.contains("quaternion"),
            "{e}"
        );
        let text = format!("{HEADER}\n0.1,0.2,0.3,0,0,0,1,2,3,1,0,0\n");
        let e = err(&text);
        assert!(e.contains("line 2") && e.contains("12 fields"), "{e}");
    }

    #[test]
    fn bad_headers_are_named() {
        assert!(
            err("").contains("no header") || err("").contains("missing"),
            "{}",
            err("")
        );
        assert!(err(&format!("{HEADER}\n")).contains("no pairs"));
        assert!(err(&format!("{HEADER},extra\n")).contains("unknown column \"extra\""));
        assert!(err(&format!("{HEADER},flange_x_m\n")).contains("appears twice"));
        let no_qz = HEADER.replace(",marker_qz", "");
        assert!(err(&format!("{no_qz}\n")).contains("missing column(s) marker_qz"));
        let no_rz = HEADER.replace("flange_rz,", "");
        assert!(err(&format!("{no_rz}\n")).contains("missing column(s) flange_rz"));
        let both = format!("q1,q2,q3,q4,q5,q6,{HEADER}");
        assert!(err(&format!("{both}\n")).contains("not both"));
    }

    #[test]
    fn comments_and_column_order_are_free() {
        let text = "# a calibration run\nmarker_qw,marker_qx,marker_qy,marker_qz,marker_x_mm,marker_y_mm,marker_z_mm,flange_x_m,flange_y_m,flange_z_m,flange_rx,flange_ry,flange_rz\n# first pose\n1,0,0,0,10,20,1000,0.3,-0.2,0.4,0,3.1,0\n";
        let p = parse_pairs_csv(text, "c.csv", None).unwrap();
        assert_eq!(p.len(), 1);
        assert!((p[0].tracker_from_marker.translation.z - 1.0).abs() < 1e-15);
        assert!((p[0].base_from_flange.translation.x - 0.3).abs() < 1e-15);
    }
}
