//! Where to sweep next, from what the registration does not know yet. The scalp above the ears
//! is split into named regions (the crown, and eight around: the forehead, the left and right
//! front, sides and back, the back of the head) in the head's own frame from the nasion and the
//! preauricular points; for each, the information a thorough sweep of it would add (every sample
//! point's distance across the skin, its model error shared with its neighbours as in the fit)
//! is added to what the registration holds, and the region that lowers the worst error bound at
//! the targets most is the one to sweep.

use crate::bound::norm_quantile;
use crate::noise::NoiseModel;
use crate::registration::{CONFIDENCE, ImageLandmark, error_covariance_at};
use crate::scalp::Scalp;
use crate::solve::surface_row;
use mocomp_geom::nalgebra::{Matrix6, Point3, Unit, Vector3};

/// Directions the scalp is sampled along (a Fibonacci sphere).
const DIRECTIONS: usize = 600;
/// Below this elevation over the ears' plane lies the face and the neck, which no sweep is
/// asked of, rad.
const LOWEST_RAD: f64 = -0.26;
/// Above this elevation lies the crown, rad.
const CROWN_RAD: f64 = 0.96;

/// A region of the scalp: its name and sample points on it (image frame) with their outward
/// normals.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    /// What to call it.
    pub name: &'static str,
    /// Points on it and the outward normal at each.
    pub points: Vec<(Point3<f64>, Vector3<f64>)>,
}

/// The regions of `scalp` in the frame `image` (the image's landmarks on the scalp) sets: the
/// ears' midpoint as origin, x to the right preauricular point, y towards the nasion (or away
/// from the inion); without those landmarks, the image's RAS axes about the scalp's centre. Points on a scan's cut
/// are left out.
pub fn regions(scalp: &Scalp<'_>, image: &[ImageLandmark]) -> Vec<Region> {
    let find = |names: &[&str]| {
        image
            .iter()
            .find(|l| names.iter().any(|n| l.name.eq_ignore_ascii_case(n)))
            .map(|l| l.point)
    };
    // Forward: to the nasion, or away from the inion.
    let front = |o: Point3<f64>| {
        find(&["nasion", "nz", "nas"])
            .map(|n| n - o)
            .or_else(|| find(&["inion", "iz", "ini"]).map(|i| o - i))
    };
    let frame = match find(&["lpa"]).zip(find(&["rpa"])).and_then(|(l, r)| {
        let o = Point3::from((l.coords + r.coords) / 2.0);
        front(o).map(|f| (l, r, o, f))
    }) {
        Some((l, r, o, f)) => {
            let x = (r - l).normalize();
            let y = (f - x * f.dot(&x)).normalize();
            // The head's centre lies some way above the ears' line.
            (o + x.cross(&y) * 0.03, x, y)
        }
        None => (scalp.shape.centre(), Vector3::x(), Vector3::y()),
    };
    let (centre, x, y) = frame;
    let z = x.cross(&y);
    let names = [
        "forehead",
        "right front",
        "right side",
        "right back",
        "back of the head",
        "left back",
        "left side",
        "left front",
    ];
    let mut out: Vec<Region> = names
        .iter()
        .chain(std::iter::once(&"crown"))
        .map(|name| Region {
            name,
            points: Vec::new(),
        })
        .collect();
    let reach = scalp.shape.bounds().extent() * 2.0;
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    for i in 0..DIRECTIONS {
        let h = 1.0 - 2.0 * (i as f64 + 0.5) / DIRECTIONS as f64;
        let ring = (1.0 - h * h).sqrt();
        let a = golden * i as f64;
        let d = x * (ring * a.cos()) + y * (ring * a.sin()) + z * h;
        let elevation = h.asin();
        if elevation < LOWEST_RAD {
            continue;
        }
        let inward = Unit::new_normalize(-d);
        let Some(hit) = scalp.shape.ray_hit(&(centre + d * reach), &inward, reach) else {
            continue;
        };
        if scalp.on_cut(&hit.point) {
            continue;
        }
        let k = if elevation >= CROWN_RAD {
            8
        } else {
            let azimuth = d.dot(&x).atan2(d.dot(&y));
            (((azimuth / std::f64::consts::FRAC_PI_4).round() as i64).rem_euclid(8)) as usize
        };
        out[k].points.push((hit.point, hit.normal.into_inner()));
    }
    out.retain(|r| !r.points.is_empty());
    out
}

/// The worst error bound over `targets` for a registration holding `information`, m.
pub fn worst_bound(information: &Matrix6<f64>, targets: &[Point3<f64>]) -> f64 {
    let Some(cov) = information.cholesky().map(|c| c.inverse()) else {
        return f64::INFINITY;
    };
    targets
        .iter()
        .map(|t| norm_quantile(&error_covariance_at(&cov, t), CONFIDENCE))
        .fold(0.0, f64::max)
}

/// Points on the skin (image frame) with their outward normals.
pub type SkinPoints = [(Point3<f64>, Vector3<f64>)];

/// The information `points` hold: each one's distance across the skin, its correlated error
/// shared with the points near it (as the fit weighs them).
pub fn surface_information(points: &SkinPoints, noise: &NoiseModel) -> Matrix6<f64> {
    let at: Vec<Point3<f64>> = points.iter().map(|(p, _)| *p).collect();
    points
        .iter()
        .zip(noise.shared_weights(&at))
        .map(|((p, n), w)| {
            let j = surface_row(p, n);
            j * j.transpose() * w
        })
        .sum()
}

/// The region whose thorough sweep would lower the worst bound at `targets` most, with that
/// bound after it (m), when it lowers it at all. What a region adds is what the sweep so far
/// (`swept`, image frame) and it hold together less what the sweep holds alone: a region swept
/// already has little left to give.
pub fn region_to_sweep<'r>(
    regions: &'r [Region],
    information: &Matrix6<f64>,
    swept: &SkinPoints,
    noise: &NoiseModel,
    targets: &[Point3<f64>],
) -> Option<(&'r Region, f64)> {
    let now = worst_bound(information, targets);
    let had = surface_information(swept, noise);
    regions
        .iter()
        .map(|r| {
            let both: Vec<(Point3<f64>, Vector3<f64>)> =
                swept.iter().chain(&r.points).copied().collect();
            let added = surface_information(&both, noise) - had;
            (r, worst_bound(&(information + added), targets))
        })
        .filter(|(_, after)| *after < now * 0.98)
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Isometry3;
    use mocomp_head::{Ellipsoid, HeadShape};

    #[test]
    fn a_head_has_nine_regions_and_a_region_swept_already_is_not_asked_for_again() {
        let head = Ellipsoid::new(Isometry3::identity(), Vector3::new(0.075, 0.095, 0.11)).unwrap();
        let scalp = Scalp::whole(&head);
        let mark = |name: &str, d: Vector3<f64>| {
            let s = head.nearest(&Point3::from(d * 0.2));
            ImageLandmark {
                name: name.into(),
                point: s.point,
                normal: s.normal.into_inner(),
                offset_m: 0.0,
            }
        };
        let image = [
            mark("nasion", Vector3::new(0.0, 1.0, -0.2)),
            mark("lpa", Vector3::new(-1.0, 0.0, -0.2)),
            mark("rpa", Vector3::new(1.0, 0.0, -0.2)),
        ];
        let all = regions(&scalp, &image);
        assert_eq!(all.len(), 9);
        let named = |n: &str| all.iter().find(|r| r.name == n).unwrap();
        assert!(named("crown").points.iter().all(|(p, _)| p.z > 0.08));
        assert!(named("forehead").points.iter().all(|(p, _)| p.y > 0.04));
        assert!(named("left side").points.iter().all(|(p, _)| p.x < -0.04));
        // What a sweep of the forehead alone leaves: the back of the head poorly fixed along y
        // and in its turns; a target at the back asks for the back.
        let noise = NoiseModel::default();
        let swept = &named("forehead").points;
        let mut info = surface_information(swept, &noise);
        info += Matrix6::identity() * 1.0; // landmarks' weak hold on everything
        let back = [Point3::new(0.0, -0.09, 0.03)];
        let (r, after) = region_to_sweep(&all, &info, swept, &noise, &back).unwrap();
        assert_ne!(r.name, "forehead", "swept already");
        assert!(after < worst_bound(&info, &back));
    }
}
