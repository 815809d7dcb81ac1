//! Contact between the coil and the head: what the simulated force sensor reads when the coil
//! presses on the scalp.
//!
//! The scalp over the skull is a stiff spring with damping along the coil's approach axis: the
//! coil model's deepest point below the head model's surface (`depth`, m) gives a force
//! `k · depth + c · d(depth)/dt` pushing the coil back along its axis (never pulling it in). The
//! default stiffness is ISO/TS 15066 Annex A's effective spring constant for the skull and
//! forehead, 150 N/mm (the stiffest body region; the scalp's soft tissue is softer at first, so
//! this overstates the force of a light touch and is the safe side for limits). The damping
//! defaults to 1,000 N·s/m (about 0.8 of critical for a 1 kg coil on that spring), an assumption:
//! no published figure for the scalp was found. The sensor adds a constant bias and white noise
//! (defaults 0: an ideal sensor), as a real one does before zeroing.

use mocomp_control::{CoilModel, HeadModel};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// The contact law's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactParams {
    /// Stiffness, N/m (ISO/TS 15066 skull/forehead: 150 N/mm).
    pub stiffness_n_m: f64,
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
            stiffness_n_m: 150_000.0,
            damping_n_s_m: 1_000.0,
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
            rng: ChaCha8Rng::seed_from_u64(seed),
        }
    }

    /// How deep the coil at `head_from_coil` is below the scalp, m (0 when clear).
    pub fn depth(&self, head_from_coil: &Isometry3<f64>) -> f64 {
        (-self.coil.distance(&self.head, head_from_coil)).max(0.0)
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
            (p.stiffness_n_m * depth + p.damping_n_s_m * rate).max(0.0)
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
        HeadModel {
            head_from_ellipsoid: Isometry3::identity(),
            radii: Vector3::new(0.075, 0.095, 0.11),
        }
    }

    fn coil() -> CoilModel {
        CoilModel {
            radius: 0.04,
            thickness: 0.03,
        }
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
        // 0.2 mm in, held still: 150 N/mm times the depth the head model gives (its distance is
        // a lower bound, scaled by the smallest semi-axis: about 0.14 mm here), upwards.
        let mut c = Contact::new(ContactParams::default(), head(), coil(), 1);
        c.wrench(0.0, &on_top(-0.0002), &base_from_head);
        let w = c.wrench(0.001, &on_top(-0.0002), &base_from_head);
        let depth = c.depth(&on_top(-0.0002));
        assert!(depth > 0.0001 && depth <= 0.0002, "{depth}");
        assert!((w[2] - 150_000.0 * depth).abs() < 1e-9, "{w:?}");
        assert!(w[0].abs() < 1e-9 && w[1].abs() < 1e-9);
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
        let expected = p.stiffness_n_m * d1 + p.damping_n_s_m * (d1 - d0) / 0.001;
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
        let mean_z = a.iter().map(|w| w[2]).sum::<f64>() / a.len() as f64;
        assert!((mean_z - 1.0).abs() < 0.03, "{mean_z}");
        let sd_x = (a.iter().map(|w| (w[0] - 0.5).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
        assert!((sd_x - 0.2).abs() < 0.02, "{sd_x}");
    }
}
