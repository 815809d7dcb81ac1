//! What a registration's inputs are worth, stated before the fit and never learned from its
//! residuals: a fit that discounted whatever disagreed with it would discount the landmarks that
//! stop a surface fit sliding on a round crown. Each figure is an error in metres, 1σ.
//!
//! - A **touched landmark** lies on the skin, so its error is mostly along the skin: where the
//!   operator's tip landed against the anatomical point ([`NoiseModel::touch_sigma_m`]) and where
//!   the image's landmark was placed against the same point
//!   ([`NoiseModel::image_landmark_sigma_m`]). Across the skin it has the tip pressing in, the
//!   head model's own error and the tracker's.
//! - A **swept point** is off the model's scalp along its normal by the tracker's noise, the skin
//!   giving under the tip (`0…skin_compression_m`, its mean expected), and the model's error
//!   against the patient's skin. That error is smooth over the head (a segmentation that runs
//!   outward over one region runs outward over its neighbours), and so is the give (a hand
//!   presses alike along a stroke): both are correlated over
//!   [`NoiseModel::model_correlation_m`], so a hundred points on one patch count as about one;
//!   and the model has a part common to the whole head ([`NoiseModel::model_offset_m`]: a
//!   threshold that puts the whole scalp in or out).

use mocomp_geom::nalgebra::{Matrix3, Point3, Vector3};

/// The noise a registration is weighed by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseModel {
    /// Where a touch lands on the skin against the anatomical point, per axis along the skin, m.
    pub touch_sigma_m: f64,
    /// Where the image's landmark lies against the same point, per axis along the scalp, m.
    pub image_landmark_sigma_m: f64,
    /// The tracked tip's noise, per axis, m.
    pub tracker_sigma_m: f64,
    /// The skin gives under the tip by 0 to this, evenly, m.
    pub skin_compression_m: f64,
    /// The head model's error against the patient's skin along the normal, m.
    pub model_sigma_m: f64,
    /// Over what distance that error is alike, m.
    pub model_correlation_m: f64,
    /// The part of that error common to the whole head (the model in or out as a whole), m.
    pub model_offset_m: f64,
}

impl Default for NoiseModel {
    /// A clinical optical tracker (0.25 mm per axis at the tip), landmarks touched and placed
    /// within 1 mm RMS along the skin each (0.7 mm per axis), the skin giving up to 1 mm, and a
    /// scalp segmented from a 1–2 mm T1 within 0.5 mm, alike over 20 mm, and in or out as a whole
    /// by 0.3 mm.
    fn default() -> Self {
        Self {
            touch_sigma_m: 0.7e-3,
            image_landmark_sigma_m: 0.7e-3,
            tracker_sigma_m: 0.25e-3,
            skin_compression_m: 1e-3,
            model_sigma_m: 0.5e-3,
            model_correlation_m: 0.02,
            model_offset_m: 0.3e-3,
        }
    }
}

/// A figure of the noise model out of range: its name and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key}: {why}")]
pub struct NoiseError {
    /// The field.
    pub key: &'static str,
    /// What is wrong with it.
    pub why: String,
}

impl NoiseModel {
    /// Every figure finite and in range: errors from 0 up to 20 mm, a correlation from 1 mm up
    /// to 200 mm.
    pub fn validate(&self) -> Result<(), NoiseError> {
        let fields = [
            ("touch_sigma", self.touch_sigma_m),
            ("image_landmark_sigma", self.image_landmark_sigma_m),
            ("tracker_sigma", self.tracker_sigma_m),
            ("skin_compression", self.skin_compression_m),
            ("model_sigma", self.model_sigma_m),
            ("model_offset", self.model_offset_m),
        ];
        for (key, v) in fields {
            if !(v.is_finite() && (0.0..=0.02).contains(&v)) {
                return Err(NoiseError {
                    key,
                    why: format!("{:.3} mm: must be 0 to 20 mm", v * 1e3),
                });
            }
        }
        // The landmarks need some error along the skin, or the information matrix is infinite.
        if self.touch_sigma_m + self.image_landmark_sigma_m + self.tracker_sigma_m <= 1e-6 {
            return Err(NoiseError {
                key: "touch_sigma",
                why: "a touched landmark with no error at all: give the touch's error".into(),
            });
        }
        if !(self.model_correlation_m.is_finite()
            && (1e-3..=0.2).contains(&self.model_correlation_m))
        {
            return Err(NoiseError {
                key: "model_correlation",
                why: format!(
                    "{:.1} mm: must be 1 to 200 mm",
                    self.model_correlation_m * 1e3
                ),
            });
        }
        Ok(())
    }

    /// How far the tip presses the skin in on average, m: the expected offset of a touched
    /// point, inward along the normal.
    pub fn mean_compression_m(&self) -> f64 {
        self.skin_compression_m / 2.0
    }

    /// The part of a swept point's variance across the skin that is its own (the tracker's), m².
    pub fn independent_variance(&self) -> f64 {
        self.tracker_sigma_m.powi(2)
    }

    /// The part it shares with the points near it (over the model's correlation length): the
    /// model's error, and the skin's give (a hand presses alike along a stroke), m².
    pub fn correlated_variance(&self) -> f64 {
        self.model_sigma_m.powi(2) + self.skin_compression_m.powi(2) / 12.0
    }

    /// Each of `points`' weight across the skin (one over its variance): its own part, and the
    /// correlated part once for every point near it (a Gaussian kernel of their distances over
    /// the correlation length, itself included), so that a patch swept densely weighs as one
    /// patch, 1/m².
    pub fn shared_weights(&self, points: &[Point3<f64>]) -> Vec<f64> {
        let k = -0.5 / self.model_correlation_m.powi(2);
        points
            .iter()
            .map(|p| {
                let near: f64 = points
                    .iter()
                    .map(|q| ((p - q).norm_squared() * k).exp())
                    .sum();
                1.0 / (self.independent_variance() + self.correlated_variance() * near)
            })
            .collect()
    }

    /// A swept point's whole variance across the skin, m².
    pub fn across_variance(&self) -> f64 {
        self.independent_variance() + self.correlated_variance() + self.model_offset_m.powi(2)
    }

    /// The covariance of a touched landmark (the touch carried into the image, less the image's
    /// landmark), where the scalp's outward unit normal is `normal`, m².
    pub fn landmark_covariance(&self, normal: &Vector3<f64>) -> Matrix3<f64> {
        let nn = normal * normal.transpose();
        let along = self.touch_sigma_m.powi(2) + self.image_landmark_sigma_m.powi(2);
        let across = self.skin_compression_m.powi(2) / 12.0
            + self.model_sigma_m.powi(2)
            + self.model_offset_m.powi(2);
        (Matrix3::identity() - nn) * along
            + nn * across
            + Matrix3::identity() * self.tracker_sigma_m.powi(2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_landmark_s_error_lies_along_the_skin_and_bad_figures_are_named() {
        let n = NoiseModel::default();
        let c = n.landmark_covariance(&Vector3::z());
        // Along the skin: 0.49 + 0.49 mm² and the tracker's; across: the compression's, the
        // model's.
        assert!((c[(0, 0)] - (0.98e-6 + 0.0625e-6)).abs() < 1e-12);
        assert!((c[(2, 2)] - (1e-6 / 12.0 + 0.25e-6 + 0.09e-6 + 0.0625e-6)).abs() < 1e-12);
        assert!(c[(0, 2)].abs() < 1e-18);
        assert!(n.validate().is_ok());
        let bad = NoiseModel {
            model_sigma_m: f64::NAN,
            ..n
        };
        assert_eq!(bad.validate().unwrap_err().key, "model_sigma");
        let bad = NoiseModel {
            model_correlation_m: 0.0,
            ..n
        };
        assert_eq!(bad.validate().unwrap_err().key, "model_correlation");
        let none = NoiseModel {
            touch_sigma_m: 0.0,
            image_landmark_sigma_m: 0.0,
            tracker_sigma_m: 0.0,
            ..n
        };
        assert_eq!(none.validate().unwrap_err().key, "touch_sigma");
    }
}
