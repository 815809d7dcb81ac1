//! Poses for `mocomp serve-poses`: a file of JSON lines, or a gently moving head.

use crate::{AppError, Context};
use mocomp_geom::iso_from_matrix_mm;
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Translation3, Vector3};
use mocomp_geom::quat_from_rotvec;
use std::path::Path;

/// A head in front of the tracker at time `t` (s): 1 m away, drifting and nodding gently.
pub fn gentle_head(t: f64) -> Isometry3<f64> {
    let w = std::f64::consts::TAU;
    let p = Vector3::new(
        0.010 * (w * 0.05 * t).sin(),
        0.005 * (w * 0.11 * t).sin(),
        1.0 + 0.004 * (w * 0.07 * t).sin(),
    );
    let r = Vector3::new(
        0.08 * (w * 0.25 * t).sin(),
        0.05 * (w * 0.13 * t).sin(),
        0.02 * (w * 0.07 * t).sin(),
    );
    Isometry3::from_parts(Translation3::from(p), quat_from_rotvec(&r))
}

/// Reads a poses file: JSON lines, each with `tracker_from_marker` (4×4 rows, mm), such as
/// `mocomp listen --json` output or a rendered `truth.jsonl`. Errors name the file and line.
pub fn read(path: &Path) -> Result<Vec<Isometry3<f64>>, AppError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).what(|| format!("--from {name}: cannot read"))?;
    let mut poses = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let at = || format!("--from {name}: line {}", i + 1);
        let v: serde_json::Value = serde_json::from_str(line).what(at)?;
        let Some(rows) = v.get("tracker_from_marker") else {
            return Err(AppError::Config(format!(
                "{}: no \"tracker_from_marker\"",
                at()
            )));
        };
        let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().unwrap_or(f64::NAN));
        poses.push(iso_from_matrix_mm(&m, 1e-4).what(at)?);
    }
    if poses.is_empty() {
        return Err(AppError::Config(format!("--from {name}: no poses")));
    }
    Ok(poses)
}
