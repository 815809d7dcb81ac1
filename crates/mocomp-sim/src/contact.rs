//! Contact between the coil and the head: what the simulated force sensor reads when the coil
//! presses on the scalp.
//!
//! The head model's surface is the scalp's. Below it are two springs in series along the coil's
//! approach axis, with a damper: the coil model's deepest point below the surface (`depth`, m)
//! first compresses the scalp (`scalp_stiffness_n_m` over `scalp_thickness_m`), then the skull
//! takes over (`skull_stiffness_n_m`), and the damper adds `c · d(depth)/dt` while pressing. The
//! force pushes the coil back out along its axis and never pulls it in.
//!
//! Defaults, and where they come from:
//! - skull: ISO/TS 15066 Annex A's effective spring constant for the skull and forehead,
//!   150 N/mm (the stiffest body region);
//! - scalp: 5 N/mm over 5 mm, an estimate: a flat punch of the coil's radius a = 40 mm on soft
//!   tissue of Young's modulus E ≈ 50 kPa (ν = 0.5) gives k = 2·E·a/(1 − ν²) ≈ 5.3 N/mm; an adult
//!   scalp is about 5 mm thick. No measured figure for a TMS coil on the scalp was found;
//! - damping: 50 N·s/m, an assumption (no published figure for the scalp was found);
//! - the sensor: no bias and no noise (an ideal sensor) unless set; a simulated world that feeds
//!   the loop's staleness rule sets noise, as a real sensor always has.

use mocomp_control::{CoilModel, HeadModel};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The noise (1σ per axis) of the force sensor in mocomp's simulated worlds (the experiment,
/// `mocomp run`'s simulated robot), N: a live sensor's reading is never constant, which the loop's
/// staleness rule relies on.
pub const SIMULATED_SENSOR_NOISE_N: f64 = 0.3;

/// The contact law's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactParams {
    /// The scalp's stiffness, N/m (5 N/mm, an estimate; see the module).
    pub scalp_stiffness_n_m: f64,
    /// The scalp's thickness: depth at which the skull takes over, m.
    pub scalp_thickness_m: f64,
    /// The skull's stiffness, N/m (ISO/TS 15066 skull/forehead: 150 N/mm).
    pub skull_stiffness_n_m: f64,
    /// Damping, N·s/m.
    pub damping_n_s_m: f64,
    /// The sensor's constant bias along each force axis, N.
    pub bias_n: [f64; 3],
    /// The sensor's noise (1σ) per force axis, N.
    pub noise_n: f64,
}

impl Default for ContactParams {
    fn default() -> Self {
        Self {
            scalp_stiffness_n_m: 5_000.0,
            scalp_thickness_m: 0.005,
            skull_stiffness_n_m: 150_000.0,
            damping_n_s_m: 50.0,
            bias_n: [0.0; 3],
            noise_n: 0.0,
        }
    }
}

/// The contact between a coil and a head, with the state its damping and noise need.
#[derive(Debug)]
pub struct Contact {
    params: ContactParams,
    head: HeadModel,
    coil: CoilModel,
    last: Option<(f64, f64)>,
    seed: u64,
    rng: ChaCha8Rng,
}

impl Contact {
    /// A contact between `coil` and `head` (their models in the loop's terms), noise seeded.
    pub fn new(params: ContactParams, head: HeadModel, coil: CoilModel, seed: u64) -> Self {
        Self {
            params,
            head,
            coil,
            last: None,
            seed,
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// Back to the state of [`Contact::new`]: the sensor's noise from its first draw, the
    /// damper with no previous depth. A world that runs several controllers restarts the contact
    /// with each run, so every run meets the same noise whatever the simulator read in between
    /// (a controller steps in real time while a client connects or a program restarts, as many
    /// times as the machine's load makes it).
    pub fn restart(&mut self) {
        self.last = None;
        self.rng = ChaCha8Rng::seed_from_u64(self.seed);
    }

    /// How deep the coil at `head_from_coil` is below the scalp, m (0 when clear).
    pub fn depth(&self, head_from_coil: &Isometry3<f64>) -> f64 {
        // The world's own scalp as it is: a mesh's sampled distance without the margin the
        // loop keeps for what may lie between the samples.
        // Only a coil below the scalp has a depth: clear (cutoff 0) is all it needs to know.
        let d = self.coil.solid().map_or(f64::INFINITY, |solid| {
            self.head
                .shape()
                .sampled_clearance_below(head_from_coil, &solid, 0.0)
        });
        (-d).max(0.0)
    }

    /// The springs' force at `depth` (m), N: scalp, then skull.
    pub fn spring_n(&self, depth: f64) -> f64 {
        let p = &self.params;
        let scalp = depth.clamp(0.0, p.scalp_thickness_m);
        let bone = (depth - p.scalp_thickness_m).max(0.0);
        p.scalp_stiffness_n_m * scalp + p.skull_stiffness_n_m * bone
    }

    /// The force the coil at `head_from_coil` presses on the scalp with, without the damper
    /// and the sensor (the truth a test compares the loop's reading with), N.
    pub fn force_n(&self, head_from_coil: &Isometry3<f64>) -> f64 {
        self.spring_n(self.depth(head_from_coil))
    }

    /// The wrench on the coil at time `t_s` (s) with the coil at `base_from_coil` and the head
    /// at `base_from_head`: force (N) and torque (N·m) in the base frame, about the coil's
    /// origin (the contact is taken on its axis, so no torque), with the sensor's bias and noise.
    pub fn wrench(
        &mut self,
        t_s: f64,
        base_from_coil: &Isometry3<f64>,
        base_from_head: &Isometry3<f64>,
    ) -> [f64; 6] {
        let depth = self.depth(&(base_from_head.inverse() * base_from_coil));
        let rate = match self.last {
            Some((t0, d0)) if t_s > t0 => (depth - d0) / (t_s - t0),
            _ => 0.0,
        };
        self.last = Some((t_s, depth));
        let p = &self.params;
        // Pushes only: a coil leaving the scalp is not held back by it.
        let push = if depth > 0.0 {
            (self.spring_n(depth) + p.damping_n_s_m * rate).max(0.0)
        } else {
            0.0
        };
        // Along the coil's axis, out of the head (+z of the coil points into it).
        let out_of_head = base_from_coil.rotation * -Vector3::z();
        let mut f = out_of_head * push;
        if p.noise_n > 0.0
            && let Ok(n) = Normal::new(0.0, p.noise_n)
        {
            f += Vector3::new(
                n.sample(&mut self.rng),
                n.sample(&mut self.rng),
                n.sample(&mut self.rng),
            );
        }
        f += Vector3::from(p.bias_n);
        [f.x, f.y, f.z, 0.0, 0.0, 0.0]
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn head() -> HeadModel {
        HeadModel::adult()
    }

    fn coil() -> CoilModel {
        CoilModel::cylinder(0.04, 0.03)
    }

    /// The coil on top of the head, its face `gap` m above the scalp, +z down into the head.
    fn on_top(gap: f64) -> Isometry3<f64> {
        Isometry3::new(
            Vector3::new(0.0, 0.0, 0.11 + gap),
            Vector3::new(std::f64::consts::PI, 0.0, 0.0),
        )
    }

    #[test]
    fn clear_of_the_head_nothing_and_pressed_in_the_spring_pushes_the_coil_out() {
        let mut c = Contact::new(ContactParams::default(), head(), coil(), 1);
        let base_from_head = Isometry3::identity();
        assert_eq!(c.wrench(0.0, &on_top(0.003), &base_from_head), [0.0; 6]);
        // 0.2 mm in, held still: the scalp's 5 N/mm times the depth the head model gives (its
        // distance is a lower bound, scaled by the smallest semi-axis: about 0.14 mm here),
        // upwards.
        let mut c = Contact::new(ContactParams::default(), head(), coil(), 1);
        c.wrench(0.0, &on_top(-0.0002), &base_from_head);
        let w = c.wrench(0.001, &on_top(-0.0002), &base_from_head);
        let depth = c.depth(&on_top(-0.0002));
        assert!(depth > 0.0001 && depth <= 0.0002, "{depth}");
        assert!((w[2] - 5_000.0 * depth).abs() < 1e-9, "{w:?}");
        assert!(w[0].abs() < 1e-9 && w[1].abs() < 1e-9);
    }

    #[test]
    fn past_the_scalp_the_skull_takes_over() {
        let c = Contact::new(ContactParams::default(), head(), coil(), 1);
        let p = ContactParams::default();
        assert_eq!(c.spring_n(0.0), 0.0);
        assert!((c.spring_n(0.002) - 10.0).abs() < 1e-9);
        // The whole scalp: 25 N; a millimetre of bone beyond it: 150 N more.
        let full = p.scalp_stiffness_n_m * p.scalp_thickness_m;
        assert!((c.spring_n(p.scalp_thickness_m) - full).abs() < 1e-9);
        assert!((c.spring_n(p.scalp_thickness_m + 0.001) - full - 150.0).abs() < 1e-9);
        // Monotonic: deeper never pushes less.
        let mut last = 0.0;
        for k in 0..100 {
            let f = c.spring_n(k as f64 * 1e-4);
            assert!(f >= last);
            last = f;
        }
    }

    #[test]
    fn damping_adds_while_pressing_in_and_never_pulls_the_coil_in() {
        let p = ContactParams::default();
        let mut c = Contact::new(p, head(), coil(), 1);
        let h = Isometry3::identity();
        c.wrench(0.0, &on_top(-0.0001), &h);
        // Pressing in: the damper adds c times the depth's rate.
        let w_in = c.wrench(0.001, &on_top(-0.0002), &h);
        let (d0, d1) = (c.depth(&on_top(-0.0001)), c.depth(&on_top(-0.0002)));
        let expected = p.scalp_stiffness_n_m * d1 + p.damping_n_s_m * (d1 - d0) / 0.001;
        assert!(
            d1 > d0 && (w_in[2] - expected).abs() < 1e-6,
            "{w_in:?} vs {expected}"
        );
        // Leaving fast: the damper would pull; the contact only pushes.
        let w_out = c.wrench(0.002, &on_top(-0.00001), &h);
        assert!(w_out[2] >= 0.0, "{w_out:?}");
    }

    #[test]
    fn the_sensor_adds_its_bias_and_seeded_noise() {
        let p = ContactParams {
            bias_n: [0.5, -0.25, 1.0],
            noise_n: 0.2,
            ..ContactParams::default()
        };
        let h = Isometry3::identity();
        let run = |seed| {
            let mut c = Contact::new(p, head(), coil(), seed);
            (0..2000)
                .map(|k| c.wrench(k as f64 * 0.002, &on_top(0.01), &h))
                .collect::<Vec<_>>()
        };
        let a = run(3);
        assert_eq!(a, run(3), "seeded");
        assert_ne!(a, run(4), "another seed, other noise");
        // Restarted after readings between runs: the same noise again.
        let mut c = Contact::new(p, head(), coil(), 3);
        for k in 0..37 {
            c.wrench(-1.0 + k as f64 * 0.002, &on_top(0.01), &h);
        }
        c.restart();
        let again: Vec<_> = (0..2000)
            .map(|k| c.wrench(k as f64 * 0.002, &on_top(0.01), &h))
            .collect();
        assert_eq!(a, again, "a restarted contact's noise");
        let mean_z = a.iter().map(|w| w[2]).sum::<f64>() / a.len() as f64;
        assert!((mean_z - 1.0).abs() < 0.03, "{mean_z}");
        let sd_x = (a.iter().map(|w| (w[0] - 0.5).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
        assert!((sd_x - 0.2).abs() < 0.02, "{sd_x}");
    }
}
