//! The sphere nearest a patch of scalp: an algebraic least-squares fit (Kåsa's: linear in the
//! centre and in `r² − |c|²`) to start, then Gauss–Newton on the points' geometric distances to
//! the sphere, which the algebraic fit biases towards small spheres on a shallow patch.

use crate::error::EfieldError;
use crate::sphere::Sphere;
use mocomp_geom::nalgebra::{Matrix4, Point3, Vector3, Vector4};

/// The fewest points a sphere is fitted to.
pub const MIN_POINTS: usize = 8;
/// Gauss–Newton's most iterations (it converges in a handful on a scalp patch).
const MAX_ITERATIONS: usize = 30;

/// The sphere nearest `points` in the least-squares sense (their distances to its surface).
pub fn fit_sphere(points: &[Point3<f64>]) -> Result<Sphere, EfieldError> {
    let degenerate = |why: &str| EfieldError::NoSphere {
        what: format!("{} scalp points: {why}", points.len()),
    };
    if points.len() < MIN_POINTS {
        return Err(degenerate("too few to fit a sphere to"));
    }
    // About their mean, for the conditioning of the normal equations.
    let mean = points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / points.len() as f64;
    let mut ata = Matrix4::zeros();
    let mut atb = Vector4::zeros();
    for p in points {
        let q = p.coords - mean;
        let row = Vector4::new(2.0 * q.x, 2.0 * q.y, 2.0 * q.z, 1.0);
        ata += row * row.transpose();
        atb += row * q.norm_squared();
    }
    let x = ata
        .lu()
        .solve(&atb)
        .ok_or_else(|| degenerate("on a plane or a line, no sphere"))?;
    let mut centre = Vector3::new(x[0], x[1], x[2]);
    let mut radius = (x[3] + centre.norm_squared()).sqrt();
    if !radius.is_finite() {
        return Err(degenerate("no sphere fits them"));
    }
    for _ in 0..MAX_ITERATIONS {
        // Residual dᵢ = |qᵢ − c| − R; its gradient in (c, R) is (−uᵢ, −1), uᵢ the unit vector
        // from c to qᵢ.
        let mut jtj = Matrix4::zeros();
        let mut jtr = Vector4::zeros();
        for p in points {
            let off = p.coords - mean - centre;
            let d = off.norm();
            if d == 0.0 {
                continue;
            }
            let u = off / d;
            let j = Vector4::new(-u.x, -u.y, -u.z, -1.0);
            jtj += j * j.transpose();
            jtr += j * (d - radius);
        }
        let Some(step) = jtj.lu().solve(&(-jtr)) else {
            break;
        };
        centre += Vector3::new(step[0], step[1], step[2]);
        radius += step[3];
        if step.norm() < 1e-12 {
            break;
        }
    }
    Sphere::new(Point3::from(centre + mean), radius)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    /// Points on a cap of a sphere (within `half_angle` of its top), jittered by `noise`.
    fn cap(centre: Vector3<f64>, r: f64, half_angle: f64, noise: f64) -> Vec<Point3<f64>> {
        let mut rng = mocomp_testkit::SplitMix64(0x2545_f491_4f6c_dd1d);
        let mut next = move || rng.next_f64();
        (0..400)
            .map(|_| {
                let theta = half_angle * next().sqrt();
                let phi = std::f64::consts::TAU * next();
                let dir = Vector3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                );
                Point3::from(centre + dir * (r + noise * (next() - 0.5)))
            })
            .collect()
    }

    #[test]
    fn a_cap_gives_back_its_sphere() {
        let c = Vector3::new(0.01, -0.02, 0.03);
        let s = fit_sphere(&cap(c, 0.09, 0.4, 0.0)).unwrap();
        assert!((s.centre.coords - c).norm() < 1e-9, "{s:?}");
        assert!((s.radius - 0.09).abs() < 1e-9, "{s:?}");
    }

    #[test]
    fn a_shallow_noisy_cap_gives_its_radius_within_two_millimetres() {
        let c = Vector3::new(0.0, 0.0, 0.0);
        // 20° of a 90 mm sphere, ±0.5 mm of noise: the algebraic fit alone shrinks it.
        let s = fit_sphere(&cap(c, 0.09, 0.35, 0.001)).unwrap();
        assert!((s.radius - 0.09).abs() < 0.002, "{s:?}");
    }

    #[test]
    fn too_few_or_flat_points_are_refused() {
        let few = vec![Point3::origin(); 3];
        assert!(fit_sphere(&few).is_err());
        let flat: Vec<_> = (0..50)
            .map(|k| Point3::new((k % 7) as f64 * 0.01, (k / 7) as f64 * 0.01, 0.0))
            .collect();
        assert!(fit_sphere(&flat).is_err());
    }
}
