//! Patient-to-image registration on landmarks: the same anatomical points named in the image
//! (RAS, from the configuration or a markups file) and touched on the patient with the
//! calibrated pointer (in the head marker's frame). The least-squares rigid fit between them
//! ([`mocomp_geom::fit::kabsch`]; never a scale or a shear) is `image_from_marker`; each
//! landmark's residual is its fiducial registration error.

use crate::NavError;
use mocomp_geom::fit::kabsch;
use mocomp_geom::nalgebra::{Isometry3, Matrix3, Point3, Vector3};

/// The least RMS distance of the landmarks from the line that fits them best, m: below it the
/// rotation about that line is barely fixed (nasion and both preauricular points are ~60 mm
/// off the line through the ears).
pub const MIN_OFF_LINE_M: f64 = 0.01;

/// A named point.
#[derive(Debug, Clone, PartialEq)]
pub struct Landmark {
    /// Its name (`nasion`, `lpa`, `rpa`, `inion`, …), matched without regard to case.
    pub name: String,
    /// Where it is, m.
    pub point: Point3<f64>,
}

impl Landmark {
    /// A landmark.
    pub fn new(name: &str, point: Point3<f64>) -> Self {
        Self {
            name: name.to_string(),
            point,
        }
    }
}

/// The registration and how well its landmarks agree.
#[derive(Debug, Clone, PartialEq)]
pub struct LandmarkRegistration {
    /// The head marker's frame to the image's (RAS), m.
    pub image_from_marker: Isometry3<f64>,
    /// Each paired landmark (image order) and the distance between its image position and its
    /// touched position carried into the image, m.
    pub residuals: Vec<(String, f64)>,
    /// Their RMS: the fiducial registration error, m.
    pub fre_m: f64,
    /// The paired landmarks in the image, for the predicted target error ([`crate::tre`]).
    pub image_points: Vec<Point3<f64>>,
}

/// Registers the `touched` landmarks (head marker frame) to the `image` ones, pairing them by
/// name; a name in only one set is left out.
pub fn register_landmarks(
    image: &[Landmark],
    touched: &[Landmark],
) -> Result<LandmarkRegistration, NavError> {
    check(image, "image")?;
    check(touched, "touched set")?;
    let pairs: Vec<(&Landmark, &Landmark)> = image
        .iter()
        .filter_map(|i| {
            touched
                .iter()
                .find(|t| t.name.eq_ignore_ascii_case(&i.name))
                .map(|t| (i, t))
        })
        .collect();
    let names: Vec<String> = pairs.iter().map(|(i, _)| i.name.clone()).collect();
    if pairs.len() < 3 {
        return Err(NavError::TooFewLandmarks { paired: names });
    }
    let from: Vec<Point3<f64>> = pairs.iter().map(|(_, t)| t.point).collect();
    let to: Vec<Point3<f64>> = pairs.iter().map(|(i, _)| i.point).collect();
    for pts in [&from, &to] {
        let off_line_m = off_line(pts);
        if off_line_m < MIN_OFF_LINE_M {
            return Err(NavError::CollinearLandmarks {
                names,
                off_line_m,
                need_m: MIN_OFF_LINE_M,
            });
        }
    }
    let (image_from_marker, fre_m) = kabsch(&from, &to).ok_or(NavError::CollinearLandmarks {
        names: names.clone(),
        off_line_m: 0.0,
        need_m: MIN_OFF_LINE_M,
    })?;
    let residuals = names
        .iter()
        .zip(from.iter().zip(&to))
        .map(|(n, (f, t))| (n.clone(), (image_from_marker * f - t).norm()))
        .collect();
    Ok(LandmarkRegistration {
        image_from_marker,
        residuals,
        fre_m,
        image_points: to,
    })
}

/// Every landmark finite, and no name twice.
fn check(set: &[Landmark], which: &'static str) -> Result<(), NavError> {
    for (k, l) in set.iter().enumerate() {
        if !l.point.coords.iter().all(|x| x.is_finite()) {
            return Err(NavError::LandmarkNotFinite {
                name: l.name.clone(),
            });
        }
        if set[..k]
            .iter()
            .any(|o| o.name.eq_ignore_ascii_case(&l.name))
        {
            return Err(NavError::DuplicateLandmark {
                name: l.name.clone(),
                set: which,
            });
        }
    }
    Ok(())
}

/// The RMS distance of `points` from the line that fits them best, m.
pub fn off_line(points: &[Point3<f64>]) -> f64 {
    let n = points.len().max(1) as f64;
    let centre: Vector3<f64> = points.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n;
    let scatter: Matrix3<f64> = points
        .iter()
        .map(|p| (p.coords - centre) * (p.coords - centre).transpose())
        .sum();
    // The scatter's two smaller eigenvalues are the squared distances from the best line.
    let mut e: Vec<f64> = scatter.symmetric_eigenvalues().iter().copied().collect();
    e.sort_by(f64::total_cmp);
    ((e[0].max(0.0) + e[1].max(0.0)) / n).sqrt()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Translation3, UnitQuaternion};
    use mocomp_geom::{rotation_error, translation_error};

    /// fsaverage's fiducials and inion-ish, image (MRI) frame, m.
    fn image() -> Vec<Landmark> {
        vec![
            Landmark::new("nasion", Point3::new(0.0015, 0.0851, -0.0348)),
            Landmark::new("lpa", Point3::new(-0.0806, -0.0291, -0.0413)),
            Landmark::new("rpa", Point3::new(0.0844, -0.0285, -0.0413)),
            Landmark::new("inion", Point3::new(0.0, -0.112, -0.02)),
        ]
    }

    #[test]
    fn touched_landmarks_register_to_the_image_exactly_and_bad_sets_are_named() {
        let marker_from_image = Isometry3::from_parts(
            Translation3::new(0.05, -0.3, 0.12),
            UnitQuaternion::from_euler_angles(0.4, -1.1, 2.0),
        );
        let touched: Vec<Landmark> = image()
            .iter()
            .rev()
            .map(|l| Landmark::new(&l.name.to_uppercase(), marker_from_image * l.point))
            .collect();
        let r = register_landmarks(&image(), &touched).unwrap();
        let truth = marker_from_image.inverse();
        assert!(rotation_error(&r.image_from_marker, &truth) < 1e-12);
        assert!(translation_error(&r.image_from_marker, &truth) < 1e-12);
        assert!(r.fre_m < 1e-12 && r.residuals.len() == 4);
        assert_eq!(r.residuals[0].0, "nasion");
        // Two only.
        let two = &touched[..2];
        match register_landmarks(&image(), two) {
            Err(NavError::TooFewLandmarks { paired }) => assert_eq!(paired.len(), 2),
            other => panic!("{other:?}"),
        }
        // Three on a line (5 mm off it at most).
        let line = vec![
            Landmark::new("a", Point3::new(0.0, 0.0, 0.0)),
            Landmark::new("b", Point3::new(0.1, 0.002, 0.0)),
            Landmark::new("c", Point3::new(0.2, 0.0, 0.001)),
        ];
        let err = register_landmarks(&line, &line).unwrap_err();
        assert!(matches!(err, NavError::CollinearLandmarks { .. }), "{err}");
        assert!(err.to_string().contains("a, b, c"), "{err}");
        // A name twice, a NaN.
        let mut twice = image();
        twice.push(Landmark::new("LPA", Point3::origin()));
        assert!(matches!(
            register_landmarks(&twice, &touched),
            Err(NavError::DuplicateLandmark { .. })
        ));
        let mut nan = touched.clone();
        nan[1].point.y = f64::NAN;
        assert!(matches!(
            register_landmarks(&image(), &nan),
            Err(NavError::LandmarkNotFinite { .. })
        ));
    }
}
