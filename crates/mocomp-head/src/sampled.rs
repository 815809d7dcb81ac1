//! The coil's clearance as the control loop asks it, several times a cycle: the least signed
//! distance over points spread on the coil's surface (its face every few millimetres, its side
//! and its back rim), ranked by the distance field's interpolated values (nanoseconds each) and
//! the nearest few refined exactly. The exact clearance ([`crate::HeadShape::coil_clearance`],
//! GJK over the triangles) costs a hundred times more; between the samples it can be less than
//! this one by what the scalp bulges between them (measured against it on real anatomy in the
//! crate's tests, and stated in the README), which the loop's least distance covers.

use crate::mesh::MeshHead;
use crate::shape::{CoilSolid, HeadShape};
use mocomp_geom::nalgebra::{Isometry3, Point3};
use std::sync::LazyLock;

/// Rings on the face (the centre, then rings of 6, 12, … points at equal steps of radius).
const FACE_RINGS: usize = 6;
/// Points on the side's middle ring and on the back's rim.
const RIM_POINTS: usize = 36;
/// Samples refined by the exact query: those whose interpolated value is within
/// [`REFINE_WITHIN_M`] of the least, at most this many.
const REFINED: usize = 2;
/// How much nearer than its sampled points the coil may be to a scalp, m: what a real scalp
/// was seen to bulge between them (1.18 mm at most on the fsaverage head, 1,150 poses facing it
/// from touching to 30 mm, tilted up to 17°; `cargo test -p mocomp-head --test coil`), with a
/// margin. The loop takes it off the sampled clearance, so it never believes in more room than
/// there is.
pub const BETWEEN_SAMPLES_M: f64 = 0.0015;

/// How far above the least interpolated value a sample is still refined, m (refining only the
/// least gave the same figures on the fsaverage scalp: a second near it is a spare).
const REFINE_WITHIN_M: f64 = 0.001;

/// The samples in the coil's own terms: (x / radius, y / radius, z / thickness).
static SAMPLES: LazyLock<Vec<[f64; 3]>> = LazyLock::new(|| {
    let mut out = vec![[0.0, 0.0, 0.0]];
    for ring in 1..=FACE_RINGS {
        let rho = ring as f64 / FACE_RINGS as f64;
        let n = 6 * ring;
        out.extend((0..n).map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            [rho * a.cos(), rho * a.sin(), 0.0]
        }));
    }
    for z in [-0.5, -1.0] {
        out.extend((0..RIM_POINTS).map(|k| {
            let a = std::f64::consts::TAU * (k as f64 + 0.5) / RIM_POINTS as f64;
            [a.cos(), a.sin(), z]
        }));
    }
    out
});

/// How many points the sampled coil has.
pub fn sample_count() -> usize {
    SAMPLES.len()
}

/// The coil's sampled points in the head frame.
pub fn surface_samples<'a>(
    coil: &'a CoilSolid,
    head_from_coil: &'a Isometry3<f64>,
) -> impl Iterator<Item = Point3<f64>> + 'a {
    let (r, t) = (coil.radius(), coil.thickness());
    SAMPLES
        .iter()
        .map(move |[x, y, z]| head_from_coil * Point3::new(r * x, r * y, t * z))
}

impl MeshHead {
    /// The coil's clearance for the loop: the least exact signed distance among its sampled
    /// points (see the module), negative when it cuts in. Where that is at least `cutoff`, any
    /// value of at least `cutoff` (the box's bound when the coil is far from the head).
    pub fn coil_clearance_sampled(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
    ) -> f64 {
        let centre = head_from_coil * Point3::new(0.0, 0.0, -coil.thickness() / 2.0);
        let reach = coil.radius().hypot(coil.thickness() / 2.0);
        let bound = self.bounds().distance(&centre) - reach;
        if bound >= cutoff {
            return bound;
        }
        // The lowest few by the interpolated field; a point beyond its grid (40 mm past the
        // head's box) ranks by the box's bound, which is far above any near point's value.
        let mut lowest = [(f64::INFINITY, Point3::origin()); REFINED];
        for p in surface_samples(coil, head_from_coil) {
            let v = self
                .field()
                .interpolated(&p)
                .unwrap_or_else(|| self.bounds().distance(&p));
            if v < lowest[REFINED - 1].0 {
                lowest[REFINED - 1] = (v, p);
                lowest.sort_by(|a, b| a.0.total_cmp(&b.0));
            }
        }
        let least = lowest[0].0;
        // Far enough by the interpolation alone, less the most it can err by.
        if least - crate::field::INTERPOLATION_SLACK_M >= cutoff {
            return least - crate::field::INTERPOLATION_SLACK_M;
        }
        lowest
            .iter()
            .filter(|(v, _)| *v <= least + REFINE_WITHIN_M)
            .map(|(_, p)| self.distance_below(p, cutoff))
            .fold(f64::INFINITY, f64::min)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn the_samples_lie_on_the_coil_and_cover_its_face() {
        let coil = CoilSolid::new(0.04, 0.03).unwrap();
        let pose = Isometry3::identity();
        let pts: Vec<_> = surface_samples(&coil, &pose).collect();
        assert_eq!(pts.len(), sample_count());
        for p in &pts {
            let radial = p.x.hypot(p.y);
            assert!(radial <= 0.04 + 1e-12 && p.z <= 0.0 && p.z >= -0.03 - 1e-12);
            // On the face, on the side or on the back's rim.
            assert!(p.z == 0.0 || (radial - 0.04).abs() < 1e-12, "{p}");
        }
        // Every point of the face is within 5 mm of a face sample.
        let face: Vec<_> = pts.iter().filter(|p| p.z == 0.0).collect();
        for i in 0..40 {
            for j in 0..40 {
                let q = Point3::new(-0.04 + 0.002 * i as f64, -0.04 + 0.002 * j as f64, 0.0);
                if q.coords.norm() > 0.04 {
                    continue;
                }
                let near = face.iter().map(|p| (*p - q).norm()).fold(1.0, f64::min);
                assert!(near < 0.005, "{q}: {near}");
            }
        }
    }
}
