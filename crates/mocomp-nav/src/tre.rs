//! The target registration error a landmark registration predicts (Fitzpatrick, West and
//! Maurer, "Predicting error in rigid-body point-based registration", IEEE TMI 1998): for N
//! fiducials localised with an RMS error FLE,
//!
//! `TRE²(r) ≈ FLE²/N · (1 + ⅓ Σₖ dₖ²/fₖ²)`,
//!
//! where, about the fiducials' principal axes through their centroid, dₖ is the target's distance
//! from axis k and fₖ the fiducials' RMS distance from it. A target far from the fiducials'
//! centroid, or off the plane they span, is registered worse than they are. The FRE does not
//! predict the TRE (a lucky fit has a small FRE), but its expected square is (1 − 2/N)·FLE²,
//! which gives the FLE an operator's touching had ([`fle_from_fre`]).

use mocomp_geom::nalgebra::{Matrix3, Point3, Vector3};

/// The RMS target registration error at `target` of a rigid fit on `fiducials` localised with an
/// RMS error `fle_m` (the 3-D error's RMS, m); infinite for fewer than three or collinear
/// fiducials.
pub fn predicted_tre(fiducials: &[Point3<f64>], fle_m: f64, target: &Point3<f64>) -> f64 {
    let n = fiducials.len();
    if n < 3 {
        return f64::INFINITY;
    }
    let centre: Vector3<f64> = fiducials.iter().map(|p| p.coords).sum::<Vector3<f64>>() / n as f64;
    let scatter: Matrix3<f64> = fiducials
        .iter()
        .map(|p| (p.coords - centre) * (p.coords - centre).transpose())
        .sum();
    let axes = scatter.symmetric_eigen().eigenvectors;
    let r = target.coords - centre;
    let mut sum = 0.0;
    for k in 0..3 {
        let e = axes.column(k);
        let off_axis = |v: &Vector3<f64>| v.norm_squared() - v.dot(&e).powi(2);
        let f2 = fiducials
            .iter()
            .map(|p| off_axis(&(p.coords - centre)))
            .sum::<f64>()
            / n as f64;
        if f2 <= 0.0 {
            return f64::INFINITY;
        }
        sum += off_axis(&r) / f2;
    }
    (fle_m * fle_m / n as f64 * (1.0 + sum / 3.0)).sqrt()
}

/// The fiducial localisation error (RMS, m) whose expected FRE over `n` fiducials is `fre_m`:
/// `FLE² = FRE² · n / (n − 2)`; infinite for fewer than three.
pub fn fle_from_fre(fre_m: f64, n: usize) -> f64 {
    if n < 3 {
        return f64::INFINITY;
    }
    fre_m * (n as f64 / (n as f64 - 2.0)).sqrt()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use crate::landmarks::{Landmark, register_landmarks};
    use mocomp_testkit::SplitMix64;

    /// The prediction against 20,000 seeded trials: fsaverage's nasion and preauricular points
    /// touched with 1 mm of Gaussian error per axis, registered, and the error measured at F3, C3
    /// and a deep target. The RMS measured TRE is the predicted one within 4 %; the FRE's
    /// squares, scaled by N/(N−2), average to the FLE's.
    #[test]
    fn the_predicted_tre_is_what_noisy_touching_gives() {
        let image = [
            Point3::new(0.0015, 0.0851, -0.0348),
            Point3::new(-0.0806, -0.0291, -0.0413),
            Point3::new(0.0844, -0.0285, -0.0413),
        ];
        let names = ["nasion", "lpa", "rpa"];
        let targets = [
            Point3::new(-0.0494, 0.0497, 0.0508),
            Point3::new(-0.067, -0.0219, 0.0712),
            Point3::new(0.0, -0.02, 0.02),
        ];
        let sigma = 1e-3;
        let fle = sigma * 3f64.sqrt();
        let image_set: Vec<Landmark> = names
            .iter()
            .zip(&image)
            .map(|(n, p)| Landmark::new(n, *p))
            .collect();
        let mut rng = SplitMix64(11);
        let (mut sq, mut fre_sq) = ([0.0; 3], 0.0);
        let trials = 20_000;
        for _ in 0..trials {
            let touched: Vec<Landmark> = names
                .iter()
                .zip(&image)
                .map(|(n, p)| {
                    let e = Vector3::new(rng.gauss(), rng.gauss(), rng.gauss()) * sigma;
                    Landmark::new(n, p + e)
                })
                .collect();
            let r = register_landmarks(&image_set, &touched).unwrap();
            fre_sq += r.fre_m * r.fre_m;
            // The truth is the identity: the error at a target is where the fit carries it.
            for (k, t) in targets.iter().enumerate() {
                sq[k] += (r.image_from_marker * t - t).norm_squared();
            }
        }
        for (k, t) in targets.iter().enumerate() {
            let measured = (sq[k] / trials as f64).sqrt();
            let predicted = predicted_tre(&image, fle, t);
            assert!(
                (measured / predicted - 1.0).abs() < 0.04,
                "target {k}: measured {measured}, predicted {predicted}"
            );
        }
        let fle_est = fle_from_fre((fre_sq / trials as f64).sqrt(), 3);
        assert!((fle_est / fle - 1.0).abs() < 0.03, "{fle_est} {fle}");
        // Farther from the fiducials, worse.
        let far = Point3::new(0.0, -0.02, 0.15);
        assert!(predicted_tre(&image, fle, &far) > predicted_tre(&image, fle, &targets[2]));
        assert!(predicted_tre(&image[..2], fle, &far).is_infinite());
    }
}
