//! Contact force: the rules on the wrench the robot reports, and the admittance that holds a
//! light contact along the coil's axis.
//!
//! The wrench is the robot state's `actual_TCP_force` (base frame; an e-Series' flange sensor or
//! a CB3's estimate, see [`mocomp_robot::ForceSource`]). Each state it is low-pass filtered
//! (`force_filter_s`), and four rules judge it, in order ([`force_rules`]):
//!
//! | rule ([`Reason`]) | fires when | reaction |
//! |---|---|---|
//! | `ForceSensorStale` | the reading has not changed for `force_stale_s` of controller time (a live sensor always carries noise) | retreat |
//! | `ForceSaturated` | a force component at the end of the sensor's range: the reading says only "at least this" | retreat |
//! | `ContactForce` | the force above `max_contact_force_n` | retreat |
//! | `ContactForceSustained` | the force above `contact_warning_force_n` for longer than `contact_warning_s` | retreat |
//!
//! Every one retreats: a coil that may be pressing on the scalp without the loop knowing how
//! hard moves off it (along its axis, following the head from `retreat_distance_m`, where no
//! force is needed to be safe) rather than standing still against a head that moves. It comes
//! back when the rule has been clear for `contact_resume_s`.
//!
//! In contact mode (`contact_mode`) the coil's place along its approach axis is not the goal's
//! fixed standoff but an admittance on the axial force: the coil presses in from the goal at
//! `(contact_force_n − F) / contact_damping_n_s_m` (at most `contact_speed_m_s`), so it settles
//! where the scalp pushes back with the set force; the pose is otherwise tracked as always. With
//! a scalp of stiffness k and the servo's lag L the admittance is stable for
//! `k · L / contact_damping_n_s_m < π/2`: with the defaults (500 N·s/m, L ≈ 35 ms) up to about
//! 20 N/mm, soft tissue; pressed onto bone it would oscillate within the speed limit, and the
//! force rules above bound it.
//!
//! Pure functions and a small state: no robot, no socket, no clock.

use crate::config::LoopParams;
use crate::supervisor::Reason;
use mocomp_geom::nalgebra::Vector3;

/// What the force rules see.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceInputs {
    /// The filtered force's magnitude, N.
    pub force_n: f64,
    /// The filtered force pushing the coil out of the head along its axis, N (negative: pulling).
    pub axial_n: f64,
    /// The newest raw reading's largest force component (absolute), N.
    pub peak_n: f64,
    /// Controller time the raw reading has not changed for, s.
    pub unchanged_s: f64,
    /// Controller time the filtered force has been above `contact_warning_force_n`, s (0 below).
    pub warned_s: f64,
}

/// The force rules, in order: stale, saturated, over the limit, over the warning level too long.
/// `range_n`: the sensor's range (`None`: an estimate without one).
pub fn force_rules(i: &ForceInputs, p: &LoopParams, range_n: Option<f64>) -> Option<Reason> {
    if i.unchanged_s > p.force_stale_s {
        return Some(Reason::ForceSensorStale(i.unchanged_s));
    }
    // A reading within 2 % of the range's end is at the end: sensors clip a little below it.
    if let Some(r) = range_n
        && i.peak_n >= 0.98 * r
    {
        return Some(Reason::ForceSaturated(i.peak_n));
    }
    if i.force_n > p.max_contact_force_n {
        return Some(Reason::ContactForce(i.force_n));
    }
    if i.warned_s > p.contact_warning_s {
        return Some(Reason::ContactForceSustained(i.force_n));
    }
    None
}

/// Whether a reason is one of the force rules' (they resume after `contact_resume_s`).
pub fn is_force_reason(r: &Reason) -> bool {
    matches!(
        r,
        Reason::ForceSensorStale(_)
            | Reason::ForceSaturated(_)
            | Reason::ContactForce(_)
            | Reason::ContactForceSustained(_)
    )
}

/// The filter and the timers behind [`ForceInputs`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceMonitor {
    filtered: Option<Vector3<f64>>,
    last_raw: [f64; 6],
    last_t: f64,
    changed_at: f64,
    warned_since: Option<f64>,
}

impl Default for ForceMonitor {
    fn default() -> Self {
        Self::new()
    }
}

impl ForceMonitor {
    /// Nothing seen yet.
    pub fn new() -> Self {
        Self {
            filtered: None,
            last_raw: [f64::NAN; 6],
            last_t: f64::NAN,
            changed_at: f64::NAN,
            warned_since: None,
        }
    }

    /// Takes the wrench of the state at controller time `t_s` (`wrench`: force N, torque N·m,
    /// base frame) with the coil's approach axis `axis` (unit, base frame, pointing into the
    /// head), and returns what the rules see. A state seen twice (same time) changes nothing.
    pub fn update(
        &mut self,
        t_s: f64,
        wrench: &[f64; 6],
        axis: &Vector3<f64>,
        p: &LoopParams,
    ) -> ForceInputs {
        let raw = Vector3::new(wrench[0], wrench[1], wrench[2]);
        let raw = if raw.iter().all(|x| x.is_finite()) {
            raw
        } else {
            // Not a number is no reading: as stale as one that stopped changing.
            Vector3::from_element(f64::NAN)
        };
        if self.changed_at.is_nan() {
            self.changed_at = t_s;
        }
        // Bitwise: a live sensor's noise changes the last bits every sample.
        let same = wrench
            .iter()
            .zip(&self.last_raw)
            .all(|(a, b)| a.to_bits() == b.to_bits());
        if !same {
            self.changed_at = t_s;
            self.last_raw = *wrench;
        }
        let dt = if self.last_t.is_finite() {
            t_s - self.last_t
        } else {
            0.0
        };
        if !(dt == 0.0 && self.filtered.is_some()) && raw.x.is_finite() {
            let f = match self.filtered {
                Some(f) if dt > 0.0 => {
                    let a = if p.force_filter_s > 0.0 {
                        1.0 - (-dt / p.force_filter_s).exp()
                    } else {
                        1.0
                    };
                    f + (raw - f) * a
                }
                _ => raw,
            };
            self.filtered = Some(f);
        }
        self.last_t = t_s;
        let f = self.filtered.unwrap_or_else(Vector3::zeros);
        let force_n = f.norm();
        // The scalp pushes the coil back out: against its approach axis.
        let axial_n = -f.dot(axis);
        if force_n > p.contact_warning_force_n {
            self.warned_since.get_or_insert(t_s);
        } else {
            self.warned_since = None;
        }
        let peak_n = if raw.x.is_finite() {
            raw.amax()
        } else {
            f64::INFINITY
        };
        ForceInputs {
            force_n,
            axial_n,
            peak_n,
            unchanged_s: if raw.x.is_finite() {
                t_s - self.changed_at
            } else {
                f64::INFINITY
            },
            warned_s: self.warned_since.map_or(0.0, |s| t_s - s),
        }
    }
}

/// One admittance step of contact mode: how far the coil is pressed in from its goal along the
/// approach axis (`press_m`, m; negative: backed off) after `dt_s` with the axial force `axial_n`.
/// It presses in at most at `contact_speed_m_s` and backs off at up to `retreat_tcp_speed_m_s`
/// (a head pushing into the coil is given way to faster than the coil ever presses). Bounded to
/// `[-retreat_distance_m, max_press_m]`.
pub fn admittance_step(
    press_m: f64,
    axial_n: f64,
    dt_s: f64,
    p: &LoopParams,
    max_press_m: f64,
) -> f64 {
    let v = ((p.contact_force_n - axial_n) / p.contact_damping_n_s_m)
        .clamp(-p.retreat_tcp_speed_m_s, p.contact_speed_m_s);
    (press_m + v * dt_s).clamp(
        -p.retreat_distance_m,
        max_press_m.max(-p.retreat_distance_m),
    )
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use crate::supervisor::{Reaction, reaction};

    fn p() -> LoopParams {
        LoopParams {
            force_sensing: true,
            ..LoopParams::default()
        }
    }

    fn quiet() -> ForceInputs {
        ForceInputs {
            force_n: 2.0,
            axial_n: 2.0,
            peak_n: 2.0,
            unchanged_s: 0.0,
            warned_s: 0.0,
        }
    }

    fn rule(f: impl FnOnce(&mut ForceInputs)) -> Option<Reason> {
        let mut i = quiet();
        f(&mut i);
        force_rules(&i, &p(), Some(50.0))
    }

    #[test]
    fn a_light_contact_is_no_rule_and_every_force_rule_retreats() {
        assert_eq!(rule(|_| {}), None);
        let p = p();
        let over = rule(|i| i.force_n = p.max_contact_force_n + 0.1).unwrap();
        assert!(matches!(over, Reason::ContactForce(_)));
        assert_eq!(rule(|i| i.force_n = p.max_contact_force_n - 0.1), None);
        let long = rule(|i| {
            i.force_n = p.contact_warning_force_n + 1.0;
            i.warned_s = p.contact_warning_s + 0.01;
        })
        .unwrap();
        assert!(matches!(long, Reason::ContactForceSustained(_)));
        assert_eq!(
            rule(|i| {
                i.force_n = p.contact_warning_force_n + 1.0;
                i.warned_s = p.contact_warning_s - 0.01;
            }),
            None
        );
        let stale = rule(|i| i.unchanged_s = p.force_stale_s + 0.001).unwrap();
        assert!(matches!(stale, Reason::ForceSensorStale(_)));
        let clipped = rule(|i| i.peak_n = 49.5).unwrap();
        assert!(matches!(clipped, Reason::ForceSaturated(_)));
        // An estimate has no range to clip at.
        let mut i = quiet();
        i.peak_n = 1e3;
        assert_eq!(force_rules(&i, &p, None), None);
        for r in [over, long, stale, clipped] {
            assert_eq!(reaction(&r), Reaction::Retreat, "{r:?}");
            assert!(is_force_reason(&r));
        }
        assert!(!is_force_reason(&Reason::HeadTooFast(1.0, 1.0)));
    }

    #[test]
    fn stale_outranks_saturated_which_outranks_the_limit() {
        let all = rule(|i| {
            i.unchanged_s = 1.0;
            i.peak_n = 60.0;
            i.force_n = 60.0;
        });
        assert!(matches!(all, Some(Reason::ForceSensorStale(_))));
        let two = rule(|i| {
            i.peak_n = 60.0;
            i.force_n = 60.0;
        });
        assert!(matches!(two, Some(Reason::ForceSaturated(_))));
    }

    /// The coil's axis pointing down (-z of the base) into a head below it.
    fn down() -> Vector3<f64> {
        -Vector3::z()
    }

    #[test]
    fn the_monitor_filters_measures_along_the_axis_and_times_its_rules() {
        let p = p();
        let mut m = ForceMonitor::new();
        // The scalp pushes the coil up (+z) with 5 N; a little noise keeps the reading alive.
        let mut last = quiet();
        for k in 0..500 {
            let t = k as f64 * 0.002;
            let noise = if k % 2 == 0 { 0.01 } else { -0.01 };
            last = m.update(t, &[0.0, 0.0, 5.0 + noise, 0.0, 0.0, 0.0], &down(), &p);
            assert!(last.unchanged_s <= 0.002 + 1e-12);
        }
        assert!((last.axial_n - 5.0).abs() < 0.02, "{last:?}");
        assert!((last.force_n - 5.0).abs() < 0.02);
        assert_eq!(last.warned_s, 0.0);
        // A step to 20 N (a little noise: a live sensor): the filter follows within a few time
        // constants.
        let mut t = 1.0;
        let mut k = 0;
        let mut at_20 = |m: &mut ForceMonitor, t: &mut f64| {
            k += 1;
            *t += 0.002;
            let w = [0.0, 0.0, 20.0 + 1e-3 * f64::from(k % 2), 0.0, 0.0, 0.0];
            (m.update(*t, &w, &down(), &p), k)
        };
        let reached = loop {
            let (r, k) = at_20(&mut m, &mut t);
            if r.axial_n > 19.0 {
                break t - 1.0;
            }
            assert!(k < 1000);
        };
        assert!(reached < 4.0 * p.force_filter_s + 0.004, "{reached}");
        // Above the warning level the time counts; it fires after contact_warning_s.
        let mut fired = None;
        for _ in 0..400 {
            let (r, _) = at_20(&mut m, &mut t);
            if let Some(reason) = force_rules(&r, &p, Some(50.0)) {
                fired = Some((r.warned_s, reason));
                break;
            }
        }
        let (warned, reason) = fired.unwrap();
        assert!(matches!(reason, Reason::ContactForceSustained(_)));
        assert!(warned > p.contact_warning_s && warned < p.contact_warning_s + 0.01);
        // A reading that stops changing is stale after force_stale_s.
        let frozen = [0.0, 0.0, 3.0, 0.0, 0.0, 0.0];
        let t0 = t;
        let mut stale_after = None;
        for _ in 0..100 {
            t += 0.002;
            let r = m.update(t, &frozen, &down(), &p);
            if let Some(Reason::ForceSensorStale(_)) = force_rules(&r, &p, Some(50.0)) {
                stale_after = Some(t - t0);
                break;
            }
        }
        let after = stale_after.unwrap();
        assert!(
            after > p.force_stale_s && after < p.force_stale_s + 0.01,
            "{after}"
        );
        // A NaN reading is no reading: stale at once.
        let r = m.update(t + 0.002, &[f64::NAN; 6], &down(), &p);
        assert!(matches!(
            force_rules(&r, &p, None),
            Some(Reason::ForceSensorStale(_))
        ));
    }

    #[test]
    fn a_pull_along_the_axis_reads_negative_and_a_side_force_counts_in_the_magnitude() {
        let p = LoopParams {
            force_filter_s: 0.0,
            ..p()
        };
        let mut m = ForceMonitor::new();
        let r = m.update(0.0, &[0.0, 0.0, -4.0, 0.0, 0.0, 0.0], &down(), &p);
        assert!((r.axial_n + 4.0).abs() < 1e-12);
        let r = m.update(0.002, &[40.0, 0.0, 0.0, 0.0, 0.0, 0.0], &down(), &p);
        assert!(r.axial_n.abs() < 1e-12);
        assert!(matches!(
            force_rules(&r, &p, None),
            Some(Reason::ContactForce(_))
        ));
    }

    #[test]
    fn the_admittance_presses_in_until_the_set_force_and_backs_off_above_it() {
        let p = p();
        // Free space: in at the speed limit.
        let s = admittance_step(0.0, 0.0, 0.002, &p, 0.01);
        let v = ((p.contact_force_n) / p.contact_damping_n_s_m).min(p.contact_speed_m_s);
        assert!((s - v * 0.002).abs() < 1e-15);
        // At the set force: still.
        assert_eq!(
            admittance_step(0.004, p.contact_force_n, 0.002, &p, 0.01),
            0.004
        );
        // Above: back out, faster than it ever presses in.
        assert!(admittance_step(0.004, p.contact_force_n + 2.0, 0.002, &p, 0.01) < 0.004);
        let out = 0.004 - admittance_step(0.004, p.contact_force_n + 50.0, 0.002, &p, 0.01);
        assert!(out > p.contact_speed_m_s * 0.002 * 5.0, "{out}");
        // Bounded by the deepest press allowed.
        assert_eq!(admittance_step(0.01, 0.0, 1.0, &p, 0.01), 0.01);
        // A closed loop on a 5 N/mm scalp 2 mm below the goal settles on the set force.
        let (k, contact_at) = (5_000.0, 0.002);
        let mut press: f64 = 0.0;
        for _ in 0..5_000 {
            let f = k * (press - contact_at).max(0.0);
            press = admittance_step(press, f, 0.002, &p, 0.01);
        }
        let f = k * (press - contact_at).max(0.0);
        assert!((f - p.contact_force_n).abs() < 0.01, "{f}");
    }
}
