//! Every parameter of the pipeline, as the seed paper's GUI exposed them, in one TOML table.
//! Units are in the key names (millimetres and pixels at this edge).

use crate::error::VisionError;
use serde::{Deserialize, Serialize};

/// How blob centroids weight their pixels.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CentroidWeighting {
    /// Every pixel counts once.
    Binary,
    /// Weight `I − threshold + 1` (less bias from the blob's rim).
    #[default]
    AboveThreshold,
    /// Weight `I`.
    Intensity,
}

/// How the pose is computed from the identified fiducials.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Registration {
    /// Least-squares rigid fit of all matched fiducials (Kabsch, with the reflection guard).
    #[default]
    Kabsch,
    /// The seed paper's frame built from three fiducials (for comparison).
    ThreePoint,
}

/// Pipeline parameters (TOML; unknown keys rejected).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackParams {
    /// IR threshold: pixels at or above it are candidates (counts, 16-bit).
    pub ir_threshold: u16,
    /// Pixels with a depth reading nearer than this are removed, mm (0 = no reading is kept).
    pub depth_min_mm: u16,
    /// Pixels with a depth reading farther than this are removed, mm.
    pub depth_max_mm: u16,
    /// Scan area `[x0, y0, x1, y1]` in pixels (half-open: x0 ≤ x < x1); `None`: whole image.
    pub scan_area: Option<[u32; 4]>,
    /// Smallest blob area, pixels.
    pub blob_area_min: u32,
    /// Largest blob area, pixels.
    pub blob_area_max: u32,
    /// Reject blobs touching the image or scan-area border (their centroids are biased).
    pub reject_edge_blobs: bool,
    /// Centroid weighting.
    pub centroid_weighting: CentroidWeighting,
    /// Width of the depth ring around a blob's bounding box, pixels.
    pub ring_px: u32,
    /// Fewest valid depth pixels in the ring; a blob with fewer is dropped.
    pub ring_min_valid: u32,
    /// Subtracted from the ring depth to get the fiducial centre's depth, mm (e.g. a sphere's
    /// radius when the ring sees the mounting surface; 0 for flat fiducials).
    pub ring_to_centre_mm: f64,
    /// Largest difference between a measured inter-fiducial distance and the geometry's, mm.
    pub match_tolerance_mm: f64,
    /// Fiducials that may be missing (only for geometries of 4 or more; at least 3 must match).
    pub max_missing: u32,
    /// Largest fiducial registration error (RMS) for a pose to count as found, mm.
    pub max_fre_mm: f64,
    /// Pose method.
    pub registration: Registration,
}

impl Default for TrackParams {
    /// Values for a Kinect at about 0.5–2.5 m from a marker with 15–30 mm fiducials.
    fn default() -> Self {
        Self {
            ir_threshold: 20_000,
            depth_min_mm: 400,
            depth_max_mm: 2_500,
            scan_area: None,
            blob_area_min: 4,
            blob_area_max: 600,
            reject_edge_blobs: true,
            centroid_weighting: CentroidWeighting::AboveThreshold,
            ring_px: 2,
            ring_min_valid: 4,
            ring_to_centre_mm: 0.0,
            match_tolerance_mm: 2.5,
            max_missing: 1,
            max_fre_mm: 4.0,
            registration: Registration::Kabsch,
        }
    }
}

impl TrackParams {
    /// Parses TOML (missing keys take their defaults) and validates.
    pub fn from_toml_str(text: &str, what: &str) -> Result<Self, VisionError> {
        let p: Self = toml::from_str(text).map_err(|e| VisionError::Config {
            what: what.to_string(),
            message: e.to_string().trim_end().replace('\n', " "),
        })?;
        p.validate(what)?;
        Ok(p)
    }

    /// Checks the values are consistent.
    pub fn validate(&self, what: &str) -> Result<(), VisionError> {
        let bad = |m: String| {
            Err(VisionError::Config {
                what: what.to_string(),
                message: m,
            })
        };
        if self.depth_min_mm >= self.depth_max_mm {
            return bad(format!(
                "depth_min_mm {} must be below depth_max_mm {}",
                self.depth_min_mm, self.depth_max_mm
            ));
        }
        if self.blob_area_min == 0 || self.blob_area_min > self.blob_area_max {
            return bad(format!(
                "blob area range [{}, {}] is empty or starts at 0",
                self.blob_area_min, self.blob_area_max
            ));
        }
        if let Some([x0, y0, x1, y1]) = self.scan_area
            && (x0 >= x1 || y0 >= y1)
        {
            return bad(format!("scan_area [{x0}, {y0}, {x1}, {y1}] is empty"));
        }
        for (name, v) in [
            ("match_tolerance_mm", self.match_tolerance_mm),
            ("max_fre_mm", self.max_fre_mm),
        ] {
            if !v.is_finite() || v <= 0.0 {
                return bad(format!("{name} must be a positive number, got {v}"));
            }
        }
        if !self.ring_to_centre_mm.is_finite() {
            return bad("ring_to_centre_mm is not a finite number".into());
        }
        if self.ring_px == 0 {
            return bad("ring_px must be at least 1".into());
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn toml_defaults_and_errors() {
        let p = TrackParams::from_toml_str(
            "ir_threshold = 30000\nscan_area = [10, 20, 500, 400]\n",
            "p",
        )
        .unwrap();
        assert_eq!(p.ir_threshold, 30000);
        assert_eq!(p.scan_area, Some([10, 20, 500, 400]));
        assert_eq!(p.blob_area_min, TrackParams::default().blob_area_min);
        let e = TrackParams::from_toml_str("threshold = 3\n", "p.toml").unwrap_err();
        assert!(e.to_string().contains("threshold"), "{e}");
        let e = TrackParams::from_toml_str("depth_min_mm = 3000\n", "p.toml").unwrap_err();
        assert!(e.to_string().contains("depth_min_mm"), "{e}");
        let e = TrackParams::from_toml_str("scan_area = [5, 5, 5, 9]\n", "p.toml").unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
        let e =
            TrackParams::from_toml_str("centroid_weighting = \"fancy\"\n", "p.toml").unwrap_err();
        assert!(e.to_string().contains("fancy"), "{e}");
    }
}
