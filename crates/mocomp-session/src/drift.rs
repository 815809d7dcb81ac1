//! The calibration drift monitor: is the tracker (or the robot's base) still where the
//! calibration says?
//!
//! A marker on the coil or the flange is seen two ways: by the tracker,
//! `base_from_tracker · tracker_from_marker`, and by the robot, `base_from_flange ·
//! flange_from_marker` (forward kinematics of the measured joints and the hand-eye calibration).
//! While the calibration holds they agree within its uncertainty and the tracker's noise. A
//! bumped camera or a moved robot base shows as an offset between them that stays. The monitor
//! low-pass filters the offset (`window_s`) so one noisy sample does not trip it, and compares it
//! with two levels: past the warning an event, past the limit the loop must hold ("calibration
//! no longer valid"). Each level is at least three standard deviations of the calibration's own
//! uncertainty.

use mocomp_geom::nalgebra::{Isometry3, Vector3};

/// The monitor's levels.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriftParams {
    /// Offset of the marker's position past which a warning is given, m. [0.001]
    pub warning_m: f64,
    /// Offset past which the calibration is no longer valid, m. [0.002]
    pub limit_m: f64,
    /// Angle past which a warning is given, rad. [0.007, 0.4°]
    pub warning_rad: f64,
    /// Angle past which the calibration is no longer valid, rad. [0.014, 0.8°]
    pub limit_rad: f64,
    /// Time constant of the filter on the offset, s. [0.05]
    pub window_s: f64,
}

impl Default for DriftParams {
    fn default() -> Self {
        Self {
            warning_m: 0.001,
            limit_m: 0.002,
            warning_rad: 0.4f64.to_radians(),
            limit_rad: 0.8f64.to_radians(),
            window_s: 0.05,
        }
    }
}

/// The monitor's verdict.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Drift {
    /// Within the warning levels.
    Ok,
    /// Past a warning level: the filtered offset (m) and angle (rad).
    Warning(f64, f64),
    /// Past a limit: the calibration is no longer valid (offset m, angle rad).
    Invalid(f64, f64),
}

/// The monitor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriftMonitor {
    params: DriftParams,
    /// The levels in use (the configured ones, at least 3σ of the calibration).
    levels: [f64; 4],
    offset: Option<Vector3<f64>>,
    angle: f64,
    last_t: f64,
    state: Drift,
}

impl DriftMonitor {
    /// A monitor with `params`, for a calibration whose marker pose is uncertain by `sigma_m` and
    /// `sigma_rad` (1σ).
    pub fn new(params: DriftParams, sigma_m: f64, sigma_rad: f64) -> Self {
        let s_m = if sigma_m.is_finite() {
            3.0 * sigma_m
        } else {
            0.0
        };
        let s_r = if sigma_rad.is_finite() {
            3.0 * sigma_rad
        } else {
            0.0
        };
        Self {
            levels: [
                params.warning_m.max(s_m),
                params.limit_m.max(s_m),
                params.warning_rad.max(s_r),
                params.limit_rad.max(s_r),
            ],
            params,
            offset: None,
            angle: 0.0,
            last_t: f64::NAN,
            state: Drift::Ok,
        }
    }

    /// The verdict now.
    pub fn state(&self) -> Drift {
        self.state
    }

    /// One sample at `t_s` of the marker seen by the tracker (`base_from_marker_tracked`) and by
    /// the robot (`base_from_marker_robot`); returns the verdict when it changed in kind.
    pub fn update(
        &mut self,
        t_s: f64,
        base_from_marker_tracked: &Isometry3<f64>,
        base_from_marker_robot: &Isometry3<f64>,
    ) -> Option<Drift> {
        let d =
            base_from_marker_tracked.translation.vector - base_from_marker_robot.translation.vector;
        let a = base_from_marker_tracked
            .rotation
            .angle_to(&base_from_marker_robot.rotation);
        if !(d.iter().all(|x| x.is_finite()) && a.is_finite()) {
            return None;
        }
        let dt = if self.last_t.is_finite() {
            (t_s - self.last_t).max(0.0)
        } else {
            0.0
        };
        self.last_t = t_s;
        let k = if self.params.window_s > 0.0 {
            1.0 - (-dt / self.params.window_s).exp()
        } else {
            1.0
        };
        let (off, ang) = match self.offset {
            None => (d, a),
            Some(o) => (o + (d - o) * k, self.angle + (a - self.angle) * k),
        };
        self.offset = Some(off);
        self.angle = ang;
        let m = off.norm();
        let [warn_m, limit_m, warn_r, limit_r] = self.levels;
        let next = if m > limit_m || ang > limit_r {
            Drift::Invalid(m, ang)
        } else if m > warn_m || ang > warn_r {
            Drift::Warning(m, ang)
        } else {
            Drift::Ok
        };
        let changed = std::mem::discriminant(&next) != std::mem::discriminant(&self.state);
        self.state = next;
        changed.then_some(next)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_testkit::SplitMix64;

    /// Feeds 60 Hz samples of a marker at rest with the tracker's noise (0.1 mm, 1 mrad per
    /// axis, seeded), the tracker bumped by `bump` from `at` on; returns the events.
    fn run(bump: Isometry3<f64>, at: f64, seconds: f64) -> Vec<(f64, Drift)> {
        let mut m = DriftMonitor::new(DriftParams::default(), 5e-5, 3e-4);
        let truth = Isometry3::new(Vector3::new(0.3, -0.1, 0.2), Vector3::new(0.2, 0.1, 2.0));
        let mut rng = SplitMix64(3);
        let mut g = || (rng.next_f64() - 0.5) * 2.0 * 3f64.sqrt();
        let mut events = Vec::new();
        for k in 0..(seconds * 60.0) as usize {
            let t = k as f64 / 60.0;
            let noise = Isometry3::new(
                Vector3::new(g(), g(), g()) * 1e-4,
                Vector3::new(g(), g(), g()) * 1e-3,
            );
            let seen = if t >= at { bump * truth } else { truth } * noise;
            if let Some(d) = m.update(t, &seen, &truth) {
                events.push((t, d));
            }
        }
        events
    }

    #[test]
    fn a_still_calibration_with_a_noisy_tracker_raises_nothing() {
        assert!(run(Isometry3::identity(), 0.0, 20.0).is_empty());
    }

    #[test]
    fn a_tracker_bumped_by_3_mm_or_1_degree_is_invalid_within_half_a_second() {
        for bump in [
            Isometry3::translation(0.003, 0.0, 0.0),
            Isometry3::rotation(Vector3::z() * 1f64.to_radians()),
        ] {
            let ev = run(bump, 2.0, 4.0);
            let invalid = ev
                .iter()
                .find(|(_, d)| matches!(d, Drift::Invalid(..)))
                .expect("invalid");
            assert!(invalid.0 >= 2.0 && invalid.0 < 2.5, "{ev:?}");
            // Nothing before the bump.
            assert!(ev.iter().all(|(t, _)| *t >= 2.0), "{ev:?}");
        }
    }

    #[test]
    fn a_small_bump_warns_only_and_the_levels_respect_the_calibrations_uncertainty() {
        let ev = run(Isometry3::translation(0.0, 0.0015, 0.0), 1.0, 3.0);
        assert!(matches!(ev.as_slice(), [(_, Drift::Warning(..))]), "{ev:?}");
        // An uncertain calibration (1σ 1 mm) does not call 2.5 mm invalid.
        let mut m = DriftMonitor::new(DriftParams::default(), 1e-3, 0.0);
        let a = Isometry3::identity();
        let b = Isometry3::translation(0.0025, 0.0, 0.0);
        assert_eq!(m.update(0.0, &b, &a), None);
        assert_eq!(m.state(), Drift::Ok);
    }
}
