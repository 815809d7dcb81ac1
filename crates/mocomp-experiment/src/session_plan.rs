//! A scripted clinical session for the lockstep experiment: a walk over named targets (a motor
//! mapping grid around the goal), a fixed time on each, and a simulated stimulator that tries to
//! pulse at set times. Its trigger is wired through the robot's gate output (a gated attempt
//! while the gate is low does not fire); an ungated attempt stands for a pulse given by hand,
//! which fires whatever the gate says and must still be logged, as off target.

use mocomp_control::HeadModel;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_session::{GridParams, SessionParams, grid_around};

/// One try of the stimulator.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Attempt {
    /// Time since the run's start, s.
    pub t_s: f64,
    /// Wired through the gate: fires only while the gate output is high.
    pub gated: bool,
}

/// The session the experiment runs.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionPlan {
    /// The gate, the drift monitor and the robot's I/O.
    pub params: SessionParams,
    /// The targets in the order visited: name and `head_from_coil` (none: the run's own goal
    /// throughout).
    pub targets: Vec<(String, Isometry3<f64>)>,
    /// Time on each target (from its selection to the next), s.
    pub per_target_s: f64,
    /// The stimulator's tries, in time order.
    pub attempts: Vec<Attempt>,
}

/// The fastest repetitive protocol a pulsing session takes, Hz (rTMS runs at up to 50 Hz in
/// bursts; the experiment's pulse lasts two cycles of the loop's 500 Hz).
pub const MAX_PULSE_RATE_HZ: f64 = 50.0;

/// The digital output the experiment's gate drives and the input its stimulator pulses.
pub const GATE_OUTPUT: u32 = 7;
/// See [`GATE_OUTPUT`].
pub const PULSE_INPUT: u32 = 0;

impl SessionPlan {
    /// A grid of targets around `goal` on `head`, `per_target_s` on each. On each target: one
    /// pulse by hand just after its selection and one through the gate a tenth of the way in
    /// (both while the coil travels: the first fires and is logged off target, the gate
    /// withholds the second), then `gated` pulses through the gate over the last 40 % of its
    /// time.
    pub fn grid(
        head: &HeadModel,
        goal: &Isometry3<f64>,
        grid: &GridParams,
        per_target_s: f64,
        gated: usize,
    ) -> Result<Self, String> {
        if !(per_target_s.is_finite() && per_target_s > 0.0) {
            return Err(format!(
                "per_target_s = {per_target_s}: must be finite and > 0"
            ));
        }
        let points = grid_around(head, goal, grid).map_err(|e| e.to_string())?;
        let targets: Vec<_> = points
            .iter()
            .map(|p| (format!("r{}c{}", p.row, p.col), p.head_from_coil))
            .collect();
        let mut attempts = Vec::new();
        for i in 0..targets.len() {
            let t0 = i as f64 * per_target_s;
            attempts.push(Attempt {
                t_s: t0 + 0.02,
                gated: false,
            });
            // Through the gate while the coil travels: withheld.
            attempts.push(Attempt {
                t_s: t0 + 0.1 * per_target_s,
                gated: true,
            });
            for k in 0..gated {
                attempts.push(Attempt {
                    t_s: t0 + per_target_s * (0.6 + 0.35 * (k as f64 + 0.5) / gated as f64),
                    gated: true,
                });
            }
        }
        Ok(Self {
            params: SessionParams {
                gate_output: Some(GATE_OUTPUT),
                pulse_input: Some(PULSE_INPUT),
                ..SessionParams::default()
            },
            targets,
            per_target_s,
            attempts,
        })
    }

    /// The run's own goal, a stimulator trying a pulse through `params`' gate `rate_hz` times a
    /// second for `duration_s` (the first a period in), as a clinician's repetitive protocol.
    pub fn pulsing(params: SessionParams, duration_s: f64, rate_hz: f64) -> Result<Self, String> {
        if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= MAX_PULSE_RATE_HZ) {
            return Err(format!(
                "pulses_hz = {rate_hz}: must be in (0, {MAX_PULSE_RATE_HZ}]"
            ));
        }
        if !(duration_s.is_finite() && duration_s > 0.0) {
            return Err(format!("duration_s = {duration_s}: must be finite and > 0"));
        }
        let n = (duration_s * rate_hz).floor() as usize;
        let attempts = (1..=n)
            .map(|k| Attempt {
                t_s: k as f64 / rate_hz,
                gated: true,
            })
            .filter(|a| a.t_s < duration_s)
            .collect();
        Ok(Self {
            params: SessionParams {
                gate_output: Some(GATE_OUTPUT),
                pulse_input: Some(PULSE_INPUT),
                ..params
            },
            targets: Vec::new(),
            per_target_s: duration_s,
            attempts,
        })
    }

    /// The whole walk, s (0 without targets: the run's own length).
    pub fn duration_s(&self) -> f64 {
        self.targets.len() as f64 * self.per_target_s
    }

    /// The target selected at `t_s` into the run.
    pub fn target_at(&self, t_s: f64) -> usize {
        ((t_s / self.per_target_s).max(0.0) as usize).min(self.targets.len().saturating_sub(1))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    #[test]
    fn a_three_by_three_walk_has_a_hand_pulse_while_travelling_and_gated_ones_later() {
        let placed = Isometry3::translation(0.0, 0.01, 0.02);
        let head = HeadModel::ellipsoid(
            placed,
            mocomp_geom::nalgebra::Vector3::new(0.075, 0.095, 0.11),
        )
        .unwrap();
        let goal = placed
            * Isometry3::new(
                mocomp_geom::nalgebra::Vector3::new(0.0, 0.0, 0.11 + 0.003),
                mocomp_geom::nalgebra::Vector3::x() * std::f64::consts::PI,
            );
        let p = SessionPlan::grid(&head, &goal, &GridParams::default(), 2.0, 3).unwrap();
        assert_eq!(p.targets.len(), 9);
        assert_eq!(p.attempts.len(), 45);
        assert_eq!(p.duration_s(), 18.0);
        assert_eq!(p.target_at(0.0), 0);
        assert_eq!(p.target_at(3.9), 1);
        assert_eq!(p.target_at(99.0), 8);
        for (i, chunk) in p.attempts.chunks(5).enumerate() {
            let t0 = i as f64 * 2.0;
            assert!(!chunk[0].gated && chunk[0].t_s - t0 < 0.1);
            assert!(chunk[1].gated && chunk[1].t_s - t0 < 0.3);
            assert!(
                chunk[2..]
                    .iter()
                    .all(|a| a.gated && a.t_s > t0 + 1.2 && a.t_s < t0 + 2.0)
            );
        }
        assert!(SessionPlan::grid(&head, &goal, &GridParams::default(), 0.0, 3).is_err());
    }

    #[test]
    fn a_pulsing_session_tries_at_its_rate_through_its_gate_on_the_run_s_goal() {
        let mut params = SessionParams::default();
        params.gate.max_dose_error_pct = Some(5.0);
        let p = SessionPlan::pulsing(params, 10.0, 2.0).unwrap();
        assert!(p.targets.is_empty() && p.duration_s() == 0.0);
        assert_eq!(p.target_at(7.0), 0);
        let t: Vec<f64> = p.attempts.iter().map(|a| a.t_s).collect();
        assert_eq!(t.len(), 19);
        assert!(t.windows(2).all(|w| (w[1] - w[0] - 0.5).abs() < 1e-12) && t[0] == 0.5);
        assert!(p.attempts.iter().all(|a| a.gated));
        assert_eq!(p.params.gate.max_dose_error_pct, Some(5.0));
        assert_eq!(
            (p.params.gate_output, p.params.pulse_input),
            (Some(GATE_OUTPUT), Some(PULSE_INPUT))
        );
        for (d, hz) in [(10.0, 0.0), (10.0, 51.0), (10.0, f64::NAN), (0.0, 1.0)] {
            let e = SessionPlan::pulsing(SessionParams::default(), d, hz).unwrap_err();
            assert!(e.contains("pulses_hz") || e.contains("duration_s"), "{e}");
        }
    }
}
