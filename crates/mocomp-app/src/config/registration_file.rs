//! The registration on disk (`mocomp register` writes it, only when the registration passed its
//! checks; `[head] registration` reads it): `head_from_image` for the loop, what it is worth
//! (the pose's covariance, from which the error bound at any target is worked out later; the
//! noise it was weighed by; each landmark's error and its distance from the skin; the swept
//! points' fit), the landmarks as touched in the head marker's frame (so `mocomp register check`
//! can tell whether the marker moved on the head), and every time an operator let compensation
//! start beyond the error limit, and why. Millimetres and milliradians at the file, metres and
//! radians inside.
//!
//! ```toml
//! [registration]
//! head_from_image = [0.01, -0.2, 0.05, 0.1, 0.2, 0.3]   # m; rotation vector, rad
//! fre_mm = 1.21
//! surface_rms_mm = 0.63
//! surface_points = 288
//! surface_off_skin = 12
//! surface_on_cut = 0
//! registered_at = "Fri, 04 Dec 2026 10:00:00 GMT"
//! # the pose's covariance, a left perturbation in the image's frame about its origin:
//! # rotation (mrad) then translation (mm), 6 × 6 row by row
//! covariance_mrad_mm = [0.02, 0.0, ...]
//! [registration.noise]                # [registration.noise] as it was
//! touch_sigma_mm = 0.7
//! ...
//! [registration.landmarks.nasion]
//! image_mm = [1.5, 85.1, -34.8]      # on the scalp
//! touched_mm = [12.0, 40.2, -80.3]   # head marker frame
//! error_mm = 0.6
//! skin_mm = 0.2
//! [[override]]
//! at = "Fri, 04 Dec 2026 10:05:00 GMT"
//! target = "dlpfc"
//! tre_mm = 3.4
//! limit_mm = 3.0
//! reason = "patient cannot stay longer; accepted by Dr X"
//! ```

use crate::config::registration::NoiseSection;
use crate::{AppError, Context};
use mocomp_geom::nalgebra::{Isometry3, Matrix6, Point3, Vector3};
use mocomp_nav::Registration;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Millimetres in a metre (and milliradians in a radian).
const MILLI: f64 = 1000.0;

/// The file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegistrationFile {
    /// The registration.
    pub registration: Record,
    /// Compensation started beyond the error limit, each time.
    #[serde(default, rename = "override", skip_serializing_if = "Vec::is_empty")]
    pub overrides: Vec<Override>,
}

/// A registration and its quality.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Record {
    /// The image's frame in the head marker's: what `[head] head_from_image` takes (m, rad).
    pub head_from_image: [f64; 6],
    /// The landmarks' FRE: the RMS of their errors below, mm.
    pub fre_mm: f64,
    /// The swept points' RMS distance from the scalp, mm (0: none swept).
    pub surface_rms_mm: f64,
    /// Swept points used.
    pub surface_points: usize,
    /// Swept points left out as off the skin.
    pub surface_off_skin: usize,
    /// Swept points left out as on the scan's cut.
    pub surface_on_cut: usize,
    /// When.
    pub registered_at: String,
    /// The covariance of a left perturbation of `image_from_marker` in the image's frame about
    /// its origin: rotation (mrad) then translation (mm), 6 × 6 row by row.
    pub covariance_mrad_mm: Vec<f64>,
    /// The noise it was weighed by (`[registration.noise]` as it was).
    pub noise: NoiseSection,
    /// Each landmark used.
    pub landmarks: BTreeMap<String, LandmarkRecord>,
}

/// One landmark as used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandmarkRecord {
    /// In the image, on the scalp, RAS, mm.
    pub image_mm: [f64; 3],
    /// As touched, head marker frame, mm.
    pub touched_mm: [f64; 3],
    /// Its distance from the image's after registration, mm.
    pub error_mm: f64,
    /// The touch's distance from the scalp after registration, mm.
    pub skin_mm: f64,
}

/// An operator's override of the error limit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Override {
    /// When.
    pub at: String,
    /// The target compensation started on.
    pub target: String,
    /// The error bound there, mm.
    pub tre_mm: f64,
    /// The limit, mm.
    pub limit_mm: f64,
    /// Why, in the operator's words.
    pub reason: String,
}

fn mm(p: &Point3<f64>) -> [f64; 3] {
    (p.coords * MILLI).into()
}

impl Record {
    /// The record of `r`, weighed by `noise` (as configured), made `at` (a date).
    pub fn new(r: &Registration, noise: NoiseSection, at: &str) -> Self {
        let head_from_image = r.image_from_marker.inverse();
        let (t, v) = (
            head_from_image.translation.vector,
            head_from_image.rotation.scaled_axis(),
        );
        let landmarks = r
            .landmarks
            .iter()
            .map(|l| {
                (
                    l.name.to_lowercase(),
                    LandmarkRecord {
                        image_mm: mm(&l.image),
                        touched_mm: mm(&l.touched),
                        error_mm: l.error_m * MILLI,
                        skin_mm: l.skin_m * MILLI,
                    },
                )
            })
            .collect();
        // rad² → mrad², m² → mm², rad·m → mrad·mm: one factor of a thousand squared.
        let cov = r.covariance * (MILLI * MILLI);
        let surface = r.surface.unwrap_or(mocomp_nav::registration::SurfaceFit {
            used: 0,
            off_skin: 0,
            on_cut: 0,
            rms_m: 0.0,
            expected_rms_m: 0.0,
        });
        Self {
            head_from_image: [t.x, t.y, t.z, v.x, v.y, v.z],
            fre_mm: r.fre_m * MILLI,
            surface_rms_mm: surface.rms_m * MILLI,
            surface_points: surface.used,
            surface_off_skin: surface.off_skin,
            surface_on_cut: surface.on_cut,
            registered_at: at.to_string(),
            covariance_mrad_mm: cov.transpose().iter().copied().collect(),
            noise,
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

    /// The pose's covariance, SI (rad, m).
    pub fn covariance(&self) -> Matrix6<f64> {
        Matrix6::from_row_slice(&self.covariance_mrad_mm) / (MILLI * MILLI)
    }

    /// The radius that holds the registration's error at `target` (image frame) with
    /// probability [`mocomp_nav::CONFIDENCE`], m.
    pub fn tre_at(&self, target: &Point3<f64>) -> f64 {
        let c = mocomp_nav::registration::error_covariance_at(&self.covariance(), target);
        mocomp_nav::bound::norm_quantile(&c, mocomp_nav::CONFIDENCE)
    }

    /// A landmark as touched (head marker frame, m), by name without regard to case.
    pub fn touched(&self, name: &str) -> Option<Point3<f64>> {
        self.landmarks
            .iter()
            .find(|(k, _)| k.eq_ignore_ascii_case(name))
            .map(|(_, l)| Point3::from(l.touched_mm) / MILLI)
    }
}

/// Reads a registration file, every value checked.
pub fn load(path: &Path) -> Result<RegistrationFile, AppError> {
    let text = std::fs::read_to_string(path)
        .what(|| format!("reading the registration {}", path.display()))?;
    let file: RegistrationFile = toml::from_str(&text).map_err(|e| {
        let old = e.to_string().contains("covariance_mrad_mm");
        AppError::Config(format!(
            "{}: {e}{}",
            path.display(),
            if old {
                " (a registration written before mocomp stated its error bound: register again)"
            } else {
                ""
            }
        ))
    })?;
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
    if !(r.fre_mm.is_finite() && r.surface_rms_mm.is_finite()) {
        return bad("fre_mm or surface_rms_mm");
    }
    if r.covariance_mrad_mm.len() != 36 || !r.covariance_mrad_mm.iter().all(|v| v.is_finite()) {
        return Err(AppError::Config(format!(
            "{}: registration.covariance_mrad_mm: {} numbers, 36 finite ones expected",
            path.display(),
            r.covariance_mrad_mm.len()
        )));
    }
    if r.covariance().cholesky().is_none() {
        return Err(AppError::Config(format!(
            "{}: registration.covariance_mrad_mm is not a covariance (not positive definite)",
            path.display()
        )));
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
    crate::files::whole::write_whole(path, text.as_bytes(), "the registration")
}
