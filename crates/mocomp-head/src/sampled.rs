//! The coil's clearance as the control loop asks it, several times a cycle: the least signed
//! distance over points spread on the coil's surface (its face every few millimetres, its side
//! and its back rim), ranked by the distance field's interpolated values (nanoseconds each) and
//! the nearest few refined exactly. The exact clearance ([`crate::HeadShape::coil_clearance`],
//! GJK on the triangles that can be nearest) costs several times more, and the more the larger
//! the mesh; between the samples it can be less than this one by what the scalp bulges between
//! them (measured against it on real anatomy in the crate's tests, and stated in the book's page on the patient's head),
//! which the loop's least distance covers. Each of the loop's call sites keeps a
//! [`ClearanceMemory`] from one cycle to the next, which spares the samples that cannot have
//! become the nearest since (the same answer, a fraction of the work).

use crate::field::{EXACT_BAND_M, INTERPOLATION_SLACK_M};
use crate::mesh::MeshHead;
use crate::shape::{CoilSolid, HeadShape, SolidKey};
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

/// [`BETWEEN_SAMPLES_M`] for a casing's samples ([`crate::casing`]): 1.75 mm at most on the
/// fsaverage head with SimNIBS's Magstim D70 (505 samples; 1,100 clear poses facing it from
/// touching to 30 mm, tilted up to 17°; the same with other spacings of face and rim), with a
/// margin.
pub const CASING_BETWEEN_SAMPLES_M: f64 = 0.002;

/// How much nearer than its sampled points `coil` may be to a scalp, m.
pub fn between_samples_m(coil: &CoilSolid) -> f64 {
    if coil.as_casing().is_some() {
        CASING_BETWEEN_SAMPLES_M
    } else {
        BETWEEN_SAMPLES_M
    }
}

/// How far above the least interpolated value a sample is still refined, m (refining only the
/// least gave the same figures on the fsaverage scalp: a second near it is a spare).
const REFINE_WITHIN_M: f64 = 0.001;

/// Below this the sampled clearance is exact (whatever the cutoff), m: the field's band, less
/// the interpolation's slack and the refinement's window.
pub const EXACT_BELOW_M: f64 = EXACT_BAND_M - INTERPOLATION_SLACK_M - REFINE_WITHIN_M;

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

/// How many points a sampled cylinder has: its face's centre and rings, and two rims.
pub const CYLINDER_SAMPLES: usize = 1 + 3 * FACE_RINGS * (FACE_RINGS + 1) + 2 * RIM_POINTS;

/// The most points any sampled coil has (a casing's, [`crate::casing::MAX_SAMPLES`]): what a
/// [`ClearanceMemory`] keeps a value for.
pub const SAMPLE_COUNT: usize = if crate::casing::MAX_SAMPLES > CYLINDER_SAMPLES {
    crate::casing::MAX_SAMPLES
} else {
    CYLINDER_SAMPLES
};

/// How many points `coil` is sampled at.
pub fn sample_count(coil: &CoilSolid) -> usize {
    match coil.as_casing() {
        Some(c) => c.samples().len(),
        None => SAMPLES.len(),
    }
}

/// The coil's sampled points in the head frame.
pub fn surface_samples<'a>(
    coil: &'a CoilSolid,
    head_from_coil: &'a Isometry3<f64>,
) -> impl Iterator<Item = Point3<f64>> + 'a {
    (0..sample_count(coil)).map(move |i| sample(coil, head_from_coil, i))
}

/// Sample `i` of the coil at `head_from_coil`, head frame.
fn sample(coil: &CoilSolid, head_from_coil: &Isometry3<f64>, i: usize) -> Point3<f64> {
    match (coil.as_cylinder(), coil.as_casing()) {
        (Some((r, t)), _) => {
            let [x, y, z] = SAMPLES[i];
            head_from_coil * Point3::new(r * x, r * y, t * z)
        }
        (None, Some(c)) => head_from_coil * c.samples()[i],
        (None, None) => head_from_coil * Point3::origin(),
    }
}

/// What one caller of [`MeshHead::coil_clearance_remembering`] knew at its last call: for
/// every sample, a lower bound of its ranked value, and the head, coil and pose they hold at.
/// A sample whose bound, lowered by as much as the coil has moved since, is still above the
/// nearest's value cannot be among the nearest, and is not looked up again. The loop asks at
/// poses a cycle apart that barely move relative to the head while it follows, so most
/// samples are spared. One memory per call site (each asks about its own pose); allocates
/// nothing.
#[derive(Debug, Clone)]
pub struct ClearanceMemory {
    /// The head, coil and pose `below` holds at; `None` when it holds nothing.
    at: Option<(u64, SolidKey, Isometry3<f64>)>,
    /// Per sample, at most its ranked value at `at`.
    below: [f64; SAMPLE_COUNT],
    /// The sample that ranked least at `at`: looked up first, so the bar starts low.
    least: usize,
    /// Samples looked up in the field, over all calls.
    looked_up: u64,
}

impl Default for ClearanceMemory {
    fn default() -> Self {
        Self::new()
    }
}

impl ClearanceMemory {
    /// A memory that knows nothing yet.
    pub fn new() -> Self {
        Self {
            at: None,
            below: [f64::NEG_INFINITY; SAMPLE_COUNT],
            least: 0,
            looked_up: 0,
        }
    }

    /// How many samples it has looked up in the field, over all its calls (of
    /// [`SAMPLE_COUNT`] a call without it): what it spared.
    pub fn looked_up(&self) -> u64 {
        self.looked_up
    }

    /// Makes the bounds hold at `head_from_coil` on `head` for `coil`: each lowered by the most
    /// the ranked value can have fallen since, or forgotten (another head or coil, or the
    /// first call).
    fn move_to(&mut self, head: &MeshHead, coil: &CoilSolid, head_from_coil: &Isometry3<f64>) {
        let fall = match &self.at {
            Some((id, c, before)) if *id == head.id() && *c == coil.key() => {
                // A sample s (coil frame) moves by at most |Δt| + ‖ΔR‖·|s|, with
                // ‖ΔR‖ = 2 sin(θ/2) for the turn θ between the poses; |s| is at most the rim
                // behind the face.
                let turn = (head_from_coil.rotation * before.rotation.inverse()).angle();
                let shift = (head_from_coil.translation.vector - before.translation.vector).norm();
                let moved = shift + 2.0 * (turn / 2.0).sin() * coil.extent();
                // f32 nodes and f64 arithmetic: far below a nanometre; a margin all the same.
                head.field().lipschitz() * moved + 1e-9
            }
            _ => f64::INFINITY,
        };
        if fall.is_finite() {
            // Only the coil's own samples hold anything (the same coil as before).
            for b in self.below.iter_mut().take(sample_count(coil)) {
                *b -= fall;
            }
        } else {
            self.below = [f64::NEG_INFINITY; SAMPLE_COUNT];
        }
        self.at = Some((head.id(), coil.key(), *head_from_coil));
    }

    /// Forgets everything (the next call looks every sample up).
    pub fn forget(&mut self) {
        self.at = None;
    }
}

impl MeshHead {
    /// The coil's clearance as the control loop takes it: the sampled clearance
    /// ([`Self::coil_clearance_sampled`], or remembering with `memory`, this call site's from
    /// its last call) less what the scalp may bulge between the samples
    /// ([`between_samples_m`]): never more room than there is. Where it is at least `cutoff`,
    /// any value of at least `cutoff`.
    pub fn loop_clearance_below(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
        memory: Option<&mut ClearanceMemory>,
    ) -> f64 {
        let margin = between_samples_m(coil);
        let cutoff = cutoff + margin;
        let sampled = match memory {
            Some(memory) => self.coil_clearance_remembering(memory, head_from_coil, coil, cutoff),
            None => self.coil_clearance_sampled(head_from_coil, coil, cutoff),
        };
        sampled - margin
    }

    /// The coil's clearance for the loop: the least exact signed distance among its sampled
    /// points (see the module), negative when it cuts in. Where that is at least `cutoff`, any
    /// value of at least `cutoff` (the box's bound when the coil is far from the head); where
    /// it is at least [`EXACT_BELOW_M`], a lower bound of it of at least that (beyond, the field
    /// holds every node at its band and cannot rank the samples).
    pub fn coil_clearance_sampled(
        &self,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
    ) -> f64 {
        self.coil_clearance_remembering(&mut ClearanceMemory::new(), head_from_coil, coil, cutoff)
    }

    /// [`Self::coil_clearance_sampled`], the same value, sparing the samples `memory` shows
    /// cannot be the nearest (see [`ClearanceMemory`]).
    pub fn coil_clearance_remembering(
        &self,
        memory: &mut ClearanceMemory,
        head_from_coil: &Isometry3<f64>,
        coil: &CoilSolid,
        cutoff: f64,
    ) -> f64 {
        let (centre, reach) = coil.bounding_sphere();
        let centre = head_from_coil * centre;
        let bound = self.bounds().distance(&centre) - reach;
        if bound >= cutoff {
            memory.forget();
            return bound;
        }
        memory.move_to(self, coil, head_from_coil);
        // The lowest few by the interpolated field (the band's value beyond its grid, 40 mm
        // past the head's box, which is above any near point's value).
        let mut lowest = [(f64::INFINITY, Point3::origin()); REFINED];
        let first = memory.least;
        let mut least_at = first;
        let count = sample_count(coil);
        let first = if first < count { first } else { 0 };
        for i in std::iter::once(first).chain((0..count).filter(|&i| i != first)) {
            // Spared: above the least by more than any refined sample can be.
            if i != first && memory.below[i] > lowest[0].0 + REFINE_WITHIN_M {
                continue;
            }
            let p = sample(coil, head_from_coil, i);
            let v = self.field().interpolated(&p).unwrap_or(EXACT_BAND_M);
            memory.below[i] = v;
            memory.looked_up += 1;
            if v < lowest[REFINED - 1].0 {
                if v < lowest[0].0 {
                    least_at = i;
                }
                lowest[REFINED - 1] = (v, p);
                lowest.sort_by(|a, b| a.0.total_cmp(&b.0));
            }
        }
        memory.least = least_at;
        let least = lowest[0].0;
        // Far enough by the interpolation alone, less the most it can err by; or so far that
        // the field, held at its band, no longer ranks the samples near the least (any could be
        // the nearest): then that bound is all it knows.
        let far = least + REFINE_WITHIN_M >= EXACT_BAND_M;
        if (far || least - INTERPOLATION_SLACK_M >= cutoff) && cutoff > -EXACT_BAND_M {
            return least - INTERPOLATION_SLACK_M;
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
        assert_eq!(pts.len(), sample_count(&coil));
        assert_eq!(sample_count(&coil), CYLINDER_SAMPLES);
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
