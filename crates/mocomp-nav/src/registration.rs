//! The whole patient-to-image registration: the landmarks' rigid fit, refined on the swept
//! scalp points when there are any, and the error it predicts at a target.
//!
//! The target registration error estimate is Fitzpatrick's from the landmarks' configuration
//! and their measured FRE, combined in quadrature with the surface fit's RMS residual. It is
//! conservative: on fsaverage (`tests/registration.rs`) the surface refinement lowers the error
//! the landmarks alone leave, while this estimate only adds to it. When in doubt, it says the
//! error is larger.

use crate::NavError;
use crate::icp::{Anchors, IcpOptions, SurfaceRegistration, refine_on_surface};
use crate::landmarks::{Landmark, LandmarkRegistration, register_landmarks};
use crate::tre::{fle_from_fre, predicted_tre};
use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_head::HeadShape;

/// A registration and what it is known to be worth.
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// The head marker's frame to the image's, m.
    pub image_from_marker: Isometry3<f64>,
    /// The landmarks' fit.
    pub landmarks: LandmarkRegistration,
    /// The surface refinement, when points were swept.
    pub surface: Option<SurfaceRegistration>,
    /// The landmarks' localisation error the FRE implies, m.
    pub fle_m: f64,
}

impl Registration {
    /// The estimated error at `target` (image frame), m.
    pub fn tre_at(&self, target: &Point3<f64>) -> f64 {
        let landmarks = predicted_tre(&self.landmarks.image_points, self.fle_m, target);
        let surface = self.surface.as_ref().map_or(0.0, |s| s.rms_m);
        landmarks.hypot(surface)
    }

    /// Every landmark's distance between the image and the touched position carried into the
    /// image by the final registration, by name, m: with a surface refinement these differ
    /// from the landmark fit's own residuals.
    pub fn landmark_errors(&self, touched: &[Landmark], image: &[Landmark]) -> Vec<(String, f64)> {
        image
            .iter()
            .filter_map(|i| {
                touched
                    .iter()
                    .find(|t| t.name.eq_ignore_ascii_case(&i.name))
                    .map(|t| {
                        (
                            i.name.clone(),
                            (self.image_from_marker * t.point - i.point).norm(),
                        )
                    })
            })
            .collect()
    }
}

/// Registers the `touched` landmarks (head marker frame) to the `image` ones, then refines on
/// the `swept` points (head marker frame; none: the landmarks alone) against `scalp` (image
/// frame).
pub fn register(
    scalp: &dyn HeadShape,
    image: &[Landmark],
    touched: &[Landmark],
    swept: &[Point3<f64>],
    options: &IcpOptions,
) -> Result<Registration, NavError> {
    let landmarks = register_landmarks(image, touched)?;
    let n = landmarks.image_points.len();
    let fle_m = fle_from_fre(landmarks.fre_m, n);
    if swept.is_empty() {
        return Ok(Registration {
            image_from_marker: landmarks.image_from_marker,
            landmarks,
            surface: None,
            fle_m,
        });
    }
    // The anchors: the touched landmarks, in the order the fit paired them.
    let anchor_marker: Vec<Point3<f64>> = landmarks
        .residuals
        .iter()
        .filter_map(|(name, _)| {
            touched
                .iter()
                .find(|t| t.name.eq_ignore_ascii_case(name))
                .map(|t| t.point)
        })
        .collect();
    let surface = refine_on_surface(
        scalp,
        swept,
        &landmarks.image_from_marker,
        Some(Anchors {
            marker: &anchor_marker,
            image: &landmarks.image_points,
            // A perfect landmark fit (FRE 0 with 3 landmarks says nothing) still has the
            // pointer's own error: no anchor is held tighter than the surface.
            fle_m: fle_m.max(options.surface_sigma_m),
        }),
        options,
    )?;
    Ok(Registration {
        image_from_marker: surface.image_from_marker,
        landmarks,
        surface: Some(surface),
        fle_m,
    })
}
