//! The registration on disk (`mocomp register` writes it, `[head] registration` reads it):
//! `head_from_image` for the loop, what it is worth (FRE per landmark, the surface fit's RMS,
//! the landmarks' localisation error, so the target error can be estimated anywhere later), the
//! landmarks as touched in the head marker's frame (so `mocomp register check` can tell whether
//! the marker moved on the head), and every time an operator let compensation start beyond the
//! error threshold, and why. Millimetres at the file, metres inside.
//!
//! ```toml
//! [registration]
//! head_from_image = [0.01, -0.2, 0.05, 0.1, 0.2, 0.3]   # m; rotation vector, rad
//! fre_mm = 0.91
//! fle_mm = 1.58
//! surface_rms_mm = 0.43
//! surface_points = 90
//! registered_at = "Fri, 04 Dec 2026 10:00:00 GMT"
//! [registration.landmarks.nasion]
//! image_mm = [1.5, 85.1, -34.8]
//! touched_mm = [12.0, 40.2, -80.3]     # head marker frame
//! error_mm = 0.6
//! [[override]]
//! at = "Fri, 04 Dec 2026 10:05:00 GMT"
//! target = "dlpfc"
//! tre_mm = 3.4
//! limit_mm = 3.0
//! reason = "patient cannot stay longer; accepted by Dr X"
//! ```

use crate::{AppError, Context};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_nav::{Landmark, Registration};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// The file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegistrationFile {
    /// The registration.
    pub registration: Record,
    /// Compensation started beyond the error threshold, each time.
    #[serde(default, rename = "override", skip_serializing_if = "Vec::is_empty")]
    pub overrides: Vec<Override>,
}

/// A registration and its quality.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Record {
    /// The image's frame in the head marker's: what `[head] head_from_image` takes (m, rad).
    pub head_from_image: [f64; 6],
    /// The landmarks' fiducial registration error, RMS, mm.
    pub fre_mm: f64,
    /// The landmarks' localisation error it implies, mm.
    pub fle_mm: f64,
    /// The swept points' RMS distance from the scalp after refinement, mm (0: none swept).
    pub surface_rms_mm: f64,
    /// Swept points used.
    pub surface_points: usize,
    /// When.
    pub registered_at: String,
    /// Each landmark used.
    pub landmarks: BTreeMap<String, LandmarkRecord>,
}

/// One landmark as used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandmarkRecord {
    /// In the image, RAS, mm.
    pub image_mm: [f64; 3],
    /// As touched, head marker frame, mm.
    pub touched_mm: [f64; 3],
    /// Its distance after registration, mm.
    pub error_mm: f64,
}

/// An operator's override of the error threshold.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Override {
    /// When.
    pub at: String,
    /// The target compensation started on.
    pub target: String,
    /// The estimated error there, mm.
    pub tre_mm: f64,
    /// The threshold, mm.
    pub limit_mm: f64,
    /// Why, in the operator's words.
    pub reason: String,
}

fn mm(p: &Point3<f64>) -> [f64; 3] {
    (p.coords * 1000.0).into()
}

impl Record {
    /// The record of `r`, from the `image` and `touched` landmarks it used, made `at` (a date).
    pub fn new(r: &Registration, image: &[Landmark], touched: &[Landmark], at: &str) -> Self {
        let head_from_image = r.image_from_marker.inverse();
        let (t, v) = (
            head_from_image.translation.vector,
            head_from_image.rotation.scaled_axis(),
        );
        let errors = r.landmark_errors(touched, image);
        let landmarks = errors
            .iter()
            .filter_map(|(name, e)| {
                let i = image.iter().find(|l| &l.name == name)?;
                let t = touched.iter().find(|l| l.name.eq_ignore_ascii_case(name))?;
                Some((
                    name.to_lowercase(),
                    LandmarkRecord {
                        image_mm: mm(&i.point),
                        touched_mm: mm(&t.point),
                        error_mm: e * 1000.0,
                    },
                ))
            })
            .collect();
        Self {
            head_from_image: [t.x, t.y, t.z, v.x, v.y, v.z],
            fre_mm: r.landmarks.fre_m * 1000.0,
            fle_mm: r.fle_m * 1000.0,
            surface_rms_mm: r.surface.as_ref().map_or(0.0, |s| s.rms_m * 1000.0),
            surface_points: r.surface.as_ref().map_or(0, |s| s.kept),
            registered_at: at.to_string(),
            landmarks,
        }
    }

    /// head_from_image.
    pub fn head_from_image(&self) -> Isometry3<f64> {
        let p = &self.head_from_image;
        Isometry3::new(
            Vector3::new(p[0], p[1], p[2]),
            Vector3::new(p[3], p[4], p[5]),
        )
    }

    /// The estimated target registration error at `target` (image frame), m: Fitzpatrick's
    /// from the landmarks and their localisation error, with the surface fit's RMS in
    /// quadrature ([`mocomp_nav::Registration::tre_at`]).
    pub fn tre_at(&self, target: &Point3<f64>) -> f64 {
        let image: Vec<Point3<f64>> = self
            .landmarks
            .values()
            .map(|l| Point3::from(l.image_mm) / 1000.0)
            .collect();
        mocomp_nav::predicted_tre(&image, self.fle_mm / 1000.0, target)
            .hypot(self.surface_rms_mm / 1000.0)
    }

    /// A landmark as touched (head marker frame, m), by name without regard to case.
    pub fn touched(&self, name: &str) -> Option<Point3<f64>> {
        self.landmarks
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, l)| Point3::from(l.touched_mm) / 1000.0)
    }
}

/// Reads a registration file, every value checked.
pub fn load(path: &Path) -> Result<RegistrationFile, AppError> {
    let text = std::fs::read_to_string(path)
        .what(|| format!("reading the registration {}", path.display()))?;
    let file: RegistrationFile =
        toml::from_str(&text).map_err(|e| AppError::Config(format!("{}: {e}", path.display())))?;
    let r = &file.registration;
    let bad = |what: &str| {
        Err(AppError::Config(format!(
            "{}: registration.{what} is not finite",
            path.display()
        )))
    };
    if !r.head_from_image.iter().all(|v| v.is_finite()) {
        return bad("head_from_image");
    }
    if !(r.fle_mm.is_finite() && r.surface_rms_mm.is_finite()) {
        return bad("fle_mm or surface_rms_mm");
    }
    if r.landmarks.len() < 3 {
        return Err(AppError::Config(format!(
            "{}: registration.landmarks: {} landmarks, a registration has at least 3",
            path.display(),
            r.landmarks.len()
        )));
    }
    Ok(file)
}

/// Writes a registration file whole (through a temporary file and a rename).
pub fn save(path: &Path, file: &RegistrationFile) -> Result<(), AppError> {
    let text =
        toml::to_string(file).map_err(|e| AppError::failed("writing the registration", e))?;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    std::fs::write(&tmp, text).what(|| format!("writing the registration {}", tmp.display()))?;
    std::fs::rename(&tmp, path).what(|| format!("writing the registration {}", path.display()))
}
