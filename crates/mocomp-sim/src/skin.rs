//! The patient's skin as the simulated operator touches it: not the head model a registration is
//! fitted to, but that model moved along its normal by a smooth random field (a segmentation is
//! off by some fraction of a millimetre, alike over a few centimetres) and by an offset common to
//! the whole head (a threshold that puts the whole scalp in or out). The field is a sum of random
//! Fourier features, whose covariance is σ²·exp(−d²/2ρ²): the kernel the registration's noise
//! model assumes, and what a registration must survive.

use mocomp_geom::nalgebra::{Isometry3, Point3, Unit, Vector3};
use mocomp_head::{Head, HeadShape};
use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Features in the field.
const FEATURES: usize = 64;

/// A smooth random scalar field over space, m.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    features: Vec<(Vector3<f64>, f64)>,
    amplitude: f64,
    offset: f64,
}

impl Field {
    /// A field of standard deviation `sigma_m`, correlated over `correlation_m`, plus an offset
    /// drawn with standard deviation `offset_m`.
    pub fn new(sigma_m: f64, correlation_m: f64, offset_m: f64, rng: &mut ChaCha8Rng) -> Self {
        let features = (0..FEATURES)
            .map(|_| {
                let w = Vector3::new(
                    rng.sample::<f64, _>(StandardNormal),
                    rng.sample::<f64, _>(StandardNormal),
                    rng.sample::<f64, _>(StandardNormal),
                ) / correlation_m.max(1e-6);
                (w, rng.random::<f64>() * std::f64::consts::TAU)
            })
            .collect();
        Self {
            features,
            amplitude: sigma_m * (2.0 / FEATURES as f64).sqrt(),
            offset: offset_m * rng.sample::<f64, _>(StandardNormal),
        }
    }

    /// The field at `p`, m.
    pub fn at(&self, p: &Point3<f64>) -> f64 {
        self.offset
            + self.amplitude
                * self
                    .features
                    .iter()
                    .map(|(w, phase)| (w.dot(&p.coords) + phase).cos())
                    .sum::<f64>()
    }
}

/// The skin: a head shape (in its own frame) seen in the image's frame, moved out along its
/// normal by a field.
#[derive(Debug, Clone)]
pub struct TrueSkin {
    head: Head,
    image_from_shape: Isometry3<f64>,
    field: Field,
}

/// A point on the skin and the skin's outward normal there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkinPoint {
    /// The point, image frame, m.
    pub point: Point3<f64>,
    /// The outward unit normal.
    pub normal: Vector3<f64>,
}

impl TrueSkin {
    /// `head` (its frame carried to the image's by `image_from_shape`), moved by `field`.
    pub fn new(head: Head, image_from_shape: Isometry3<f64>, field: Field) -> Self {
        Self {
            head,
            image_from_shape,
            field,
        }
    }

    fn moved(&self, point: Point3<f64>, normal: Unit<Vector3<f64>>) -> SkinPoint {
        let (p, n) = (
            self.image_from_shape * point,
            self.image_from_shape.rotation * normal.into_inner(),
        );
        SkinPoint {
            point: p + n * self.field.at(&p),
            normal: n,
        }
    }

    /// The skin point nearest `p` (image frame).
    pub fn nearest(&self, p: &Point3<f64>) -> SkinPoint {
        let s = self
            .head
            .nearest(&self.image_from_shape.inverse_transform_point(p));
        self.moved(s.point, s.normal)
    }

    /// The outermost skin point on the ray from `centre` along the unit `direction` (image
    /// frame), if the head lies on it.
    pub fn along(&self, centre: &Point3<f64>, direction: &Vector3<f64>) -> Option<SkinPoint> {
        let reach = self.head.bounds().extent() * 2.0;
        let from = self
            .image_from_shape
            .inverse_transform_point(&(centre + direction * reach));
        let inward = Unit::new_normalize(-(self.image_from_shape.rotation.inverse() * direction));
        self.head
            .ray_hit(&from, &inward, reach)
            .map(|h| self.moved(h.point, h.normal))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use rand::SeedableRng;

    /// The field's spread and correlation are what it was made with: 2,000 seeded fields, the
    /// spread at a point within 10 %, the correlation at one correlation length e^-½ within 0.05.
    #[test]
    fn the_field_is_as_smooth_and_as_large_as_asked() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (s, rho) = (0.5e-3, 0.02);
        let a = Point3::new(0.01, 0.02, 0.03);
        let b = a + Vector3::new(rho, 0.0, 0.0);
        let (mut aa, mut ab, mut bb) = (0.0, 0.0, 0.0);
        let n = 2000;
        for _ in 0..n {
            let f = Field::new(s, rho, 0.0, &mut rng);
            let (fa, fb) = (f.at(&a), f.at(&b));
            aa += fa * fa;
            ab += fa * fb;
            bb += fb * fb;
        }
        let sd = (aa / n as f64).sqrt();
        assert!((sd / s - 1.0).abs() < 0.1, "{sd}");
        let corr = ab / (aa * bb).sqrt();
        assert!((corr - (-0.5f64).exp()).abs() < 0.05, "{corr}");
    }
}
