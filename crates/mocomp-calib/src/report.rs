//! What a calibration reports, and its result file (TOML, metres).

use crate::error::CalibError;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{RIGID_TOLERANCE, iso_from_rows, rows_from_iso, ur_pose_from_iso};
use serde::{Deserialize, Serialize};

/// One pair's residual at the solution.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PairResidual {
    /// 0-based index in the pair set.
    pub index: usize,
    /// 1-based line in the pairs file, when known.
    pub line: Option<usize>,
    /// Distance between the marker position the robot chain predicts and the measured one, mm.
    pub translation_mm: f64,
    /// Rotation between them, degrees.
    pub rotation_deg: f64,
    /// Residual normalised by the noise model (√ of its χ² contribution; about 2.3 on average for
    /// a pair that fits the model).
    pub normalized: f64,
    /// Flagged as an outlier (beyond the 99.9 % χ²₆ bound times the robust scale).
    pub outlier: bool,
    /// Used in the solution (false when left out as an outlier on request).
    pub used: bool,
}

/// 1σ uncertainty of X and Y (root-sum-square over the three axes), from the information matrix at
/// the solution scaled by the reduced χ² of the fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Uncertainty {
    /// X rotation, degrees.
    pub x_rotation_deg: f64,
    /// X translation, millimetres.
    pub x_translation_mm: f64,
    /// Y rotation, degrees.
    pub y_rotation_deg: f64,
    /// Y translation, millimetres.
    pub y_translation_mm: f64,
}

/// A transform in the result file: the 4×4 matrix (metres) and, for people, the UR pose vector.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransformEntry {
    /// Homogeneous matrix, rows, metres.
    pub matrix: [[f64; 4]; 4],
    /// `[x, y, z, rx, ry, rz]` (metres, rotation vector); informative, `matrix` is what is read.
    pub pose: [f64; 6],
}

impl TransformEntry {
    /// The entry of a transform.
    pub fn of(t: &Isometry3<f64>) -> Self {
        Self {
            matrix: rows_from_iso(t),
            pose: ur_pose_from_iso(t),
        }
    }
}

/// Summary statistics in the result file.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ResidualSummary {
    /// RMS translation residual over the pairs used, mm.
    pub rms_mm: f64,
    /// RMS rotation residual, degrees.
    pub rms_deg: f64,
    /// Largest translation residual, mm.
    pub max_mm: f64,
    /// Largest rotation residual, degrees.
    pub max_deg: f64,
}

/// The calibration result file: what the control loop loads.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CalibrationFile {
    /// Solver used.
    pub method: String,
    /// Pairs given.
    pub pairs: usize,
    /// `X = flange_from_marker`.
    #[serde(rename = "X")]
    pub x: TransformEntry,
    /// `Y = base_from_tracker`.
    #[serde(rename = "Y")]
    pub y: TransformEntry,
    /// Residual statistics.
    pub residuals: ResidualSummary,
    /// 1-based lines (or 1-based pair numbers when there were no lines) of the outlier pairs.
    pub outliers: Vec<usize>,
    /// Uncertainty of X and Y.
    pub uncertainty: Uncertainty,
}

impl CalibrationFile {
    /// As TOML text, with a comment saying what the frames are.
    pub fn to_toml_string(&self) -> Result<String, CalibError> {
        let body = toml::to_string(self).map_err(|e| CalibError::ResultFile(e.to_string()))?;
        Ok(format!(
            "# mocomp hand-eye calibration: X = flange_from_marker, Y = base_from_tracker\n\
             # (metres; base_from_flange · X = Y · tracker_from_marker)\n{body}"
        ))
    }

    /// Parses a result file; unknown keys are rejected and the matrices must be rigid.
    pub fn from_toml_str(text: &str) -> Result<Self, CalibError> {
        let f: Self = toml::from_str(text)
            .map_err(|e| CalibError::ResultFile(e.to_string().trim_end().replace('\n', " ")))?;
        f.transforms()?;
        Ok(f)
    }

    /// `(X, Y)` as transforms.
    pub fn transforms(&self) -> Result<(Isometry3<f64>, Isometry3<f64>), CalibError> {
        let x = iso_from_rows(&self.x.matrix, RIGID_TOLERANCE)
            .map_err(|e| CalibError::ResultFile(format!("X.matrix: {e}")))?;
        let y = iso_from_rows(&self.y.matrix, RIGID_TOLERANCE)
            .map_err(|e| CalibError::ResultFile(format!("Y.matrix: {e}")))?;
        Ok((x, y))
    }
}
