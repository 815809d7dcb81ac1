//! The on-target gate: whether the stimulator may fire now.
//!
//! The coil is on target when its *measured* pose (forward kinematics of the measured joints
//! with the calibration, not the command) is within `position_tolerance_m` and
//! `angle_tolerance_rad` of the target for the head as estimated now, while the loop is
//! tracking. The gate opens once that has held for `dwell_s` without a break, and shuts at the
//! first cycle it does not: leaving the tolerance, the loop leaving tracking (a planned path to
//! another target, a retreat, a hold), or no head estimate. So a pulse can never fall while the
//! coil travels between targets. With `max_dose_error_pct`, the coil must also give the target
//! its planned dose within that many percent (the field the measured coil induces there, which
//! a lift of a millimetre lowers by 4 %: the pose tolerances alone let a pulse through 8 % off);
//! a cycle without a dose (no plan for the goal, the field without an answer) is off target.
//! Each change is an event with its reason.

/// The gate's tolerances and dwell.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GateParams {
    /// The coil's largest position error on target, m. [0.002]
    pub position_tolerance_m: f64,
    /// The coil's largest angle error on target, rad. [0.035, 2°]
    pub angle_tolerance_rad: f64,
    /// How long the coil must have been on target before the gate opens, s. [0.1]
    pub dwell_s: f64,
    /// The dose's largest error, % of the planned dose (`None`: the dose is not judged; with
    /// it, a coil model is needed).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_dose_error_pct: Option<f64>,
}

impl Default for GateParams {
    fn default() -> Self {
        Self {
            position_tolerance_m: 0.002,
            angle_tolerance_rad: 2f64.to_radians(),
            dwell_s: 0.1,
            max_dose_error_pct: None,
        }
    }
}

/// Why the gate is shut.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shut {
    /// Not yet on target for `dwell_s` (since when, s).
    Dwelling(f64),
    /// The coil's position error is beyond the tolerance (m).
    PositionError(f64),
    /// The coil's angle error is beyond the tolerance (rad).
    AngleError(f64),
    /// The dose is further from the planned than `max_dose_error_pct` (the dose, % of the
    /// planned).
    DoseError(f64),
    /// The gate judges the dose and this cycle has none.
    NoDose,
    /// The loop is not tracking the target (on a path, retreating, holding, faulted).
    NotTracking,
    /// No head estimate: where the target is is unknown.
    NoHead,
}

/// The gate's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GateState {
    /// Pulses allowed.
    Open,
    /// Pulses refused, and why.
    Shut(Shut),
}

/// A change of the gate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GateEvent {
    /// On target for the dwell time: pulses allowed.
    Opened,
    /// Off target: pulses refused.
    Shut(Shut),
}

/// What the gate sees each cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateInputs {
    /// The loop tracks its goal (not on a path, not retreating or holding).
    pub tracking: bool,
    /// The measured coil's error against the target for the head now, m and rad (`None`: no
    /// head estimate).
    pub error: Option<(f64, f64)>,
    /// The dose the measured coil gives at the target, % of the planned (NaN: none).
    pub dose_pct: f64,
}

/// The gate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gate {
    params: GateParams,
    state: GateState,
    on_since: Option<f64>,
}

impl Gate {
    /// A shut gate.
    pub fn new(params: GateParams) -> Self {
        Self {
            params,
            state: GateState::Shut(Shut::NoHead),
            on_since: None,
        }
    }

    /// The state now.
    pub fn state(&self) -> GateState {
        self.state
    }

    /// Whether pulses are allowed.
    pub fn is_open(&self) -> bool {
        self.state == GateState::Open
    }

    /// One cycle at time `t_s`; the event when the gate opened or shut.
    pub fn update(&mut self, t_s: f64, i: &GateInputs) -> Option<GateEvent> {
        let p = &self.params;
        let off = match (i.tracking, i.error) {
            (false, _) => Some(Shut::NotTracking),
            (true, None) => Some(Shut::NoHead),
            // NaN is not within the tolerance.
            (true, Some((d, _))) if d.is_nan() || d > p.position_tolerance_m => {
                Some(Shut::PositionError(d))
            }
            (true, Some((_, a))) if a.is_nan() || a > p.angle_tolerance_rad => {
                Some(Shut::AngleError(a))
            }
            (true, Some(_)) => p.max_dose_error_pct.and_then(|max| {
                let pct = i.dose_pct;
                if pct.is_nan() {
                    Some(Shut::NoDose)
                } else {
                    ((pct - 100.0).abs() > max).then_some(Shut::DoseError(pct))
                }
            }),
        };
        let next = match off {
            Some(why) => {
                self.on_since = None;
                GateState::Shut(why)
            }
            None => {
                let since = *self.on_since.get_or_insert(t_s);
                if t_s - since >= p.dwell_s {
                    GateState::Open
                } else {
                    GateState::Shut(Shut::Dwelling(since))
                }
            }
        };
        let was_open = self.is_open();
        self.state = next;
        match (was_open, next) {
            (false, GateState::Open) => Some(GateEvent::Opened),
            (true, GateState::Shut(why)) => Some(GateEvent::Shut(why)),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    fn on(d: f64, a: f64) -> GateInputs {
        GateInputs {
            tracking: true,
            error: Some((d, a)),
            dose_pct: f64::NAN,
        }
    }

    fn dosed(pct: f64) -> GateInputs {
        GateInputs {
            dose_pct: pct,
            ..on(0.0005, 0.005)
        }
    }

    #[test]
    fn it_opens_after_the_dwell_on_target_and_shuts_at_once_off_it() {
        let p = GateParams::default();
        let mut g = Gate::new(p);
        let mut opened = None;
        for k in 0..100 {
            let t = k as f64 * 0.002;
            if g.update(t, &on(0.001, 0.01)) == Some(GateEvent::Opened) {
                opened = Some(t);
            }
        }
        assert!((opened.unwrap() - p.dwell_s).abs() < 0.003, "{opened:?}");
        assert!(g.is_open());
        // One cycle off in position: shut, with the error.
        let e = g.update(0.2, &on(0.0025, 0.01));
        assert_eq!(e, Some(GateEvent::Shut(Shut::PositionError(0.0025))));
        // Back on: the dwell starts again.
        assert_eq!(g.update(0.202, &on(0.001, 0.0)), None);
        assert!(matches!(g.state(), GateState::Shut(Shut::Dwelling(_))));
        assert_eq!(g.update(0.25, &on(0.001, 0.0)), None);
        assert_eq!(g.update(0.31, &on(0.001, 0.0)), Some(GateEvent::Opened));
        // The angle counts alike.
        let e = g.update(0.312, &on(0.0, p.angle_tolerance_rad * 1.01));
        assert!(matches!(e, Some(GateEvent::Shut(Shut::AngleError(_)))));
    }

    #[test]
    fn never_open_while_the_loop_does_not_track_or_the_head_is_unknown() {
        let mut g = Gate::new(GateParams::default());
        for k in 0..500 {
            let t = k as f64 * 0.002;
            // On a path through the target: within tolerance, not tracking.
            g.update(
                t,
                &GateInputs {
                    tracking: false,
                    error: Some((0.0, 0.0)),
                    dose_pct: 100.0,
                },
            );
            assert_eq!(g.state(), GateState::Shut(Shut::NotTracking));
        }
        let mut g = Gate::new(GateParams::default());
        for k in 0..100 {
            g.update(k as f64 * 0.002, &on(0.0, 0.0));
        }
        assert!(g.is_open());
        let e = g.update(
            0.3,
            &GateInputs {
                tracking: true,
                error: None,
                dose_pct: 100.0,
            },
        );
        assert_eq!(e, Some(GateEvent::Shut(Shut::NoHead)));
        // NaN errors are not "within tolerance".
        let mut g = Gate::new(GateParams::default());
        for k in 0..100 {
            g.update(k as f64 * 0.002, &on(f64::NAN, 0.0));
        }
        assert!(!g.is_open());
    }

    #[test]
    fn with_a_dose_limit_it_opens_only_on_the_planned_dose_and_never_without_one() {
        let p = GateParams {
            max_dose_error_pct: Some(3.0),
            ..GateParams::default()
        };
        // Within the pose tolerances but 4 % under the planned dose (a 1 mm lift): shut, all
        // the time, with the dose said.
        let mut g = Gate::new(p);
        for k in 0..200 {
            g.update(k as f64 * 0.002, &dosed(96.0));
            assert_eq!(g.state(), GateState::Shut(Shut::DoseError(96.0)));
        }
        // Over the planned dose by as much counts alike: the prescription is a dose, not a floor.
        g.update(0.5, &dosed(103.5));
        assert_eq!(g.state(), GateState::Shut(Shut::DoseError(103.5)));
        // No dose at all (no plan for the goal, no field): shut.
        g.update(0.6, &dosed(f64::NAN));
        assert_eq!(g.state(), GateState::Shut(Shut::NoDose));
        // Within 3 %: opens after the dwell, and shuts at the first cycle beyond.
        let mut opened = None;
        for k in 0..100 {
            let t = 1.0 + k as f64 * 0.002;
            if g.update(t, &dosed(97.5)) == Some(GateEvent::Opened) {
                opened = Some(t);
            }
        }
        assert!(
            (opened.unwrap() - 1.0 - p.dwell_s).abs() < 0.003,
            "{opened:?}"
        );
        let e = g.update(1.3, &dosed(96.9));
        assert_eq!(e, Some(GateEvent::Shut(Shut::DoseError(96.9))));
        // The pose still counts first: on the dose but off in position is a position error.
        let e = g.update(
            1.302,
            &GateInputs {
                dose_pct: 100.0,
                ..on(0.003, 0.0)
            },
        );
        assert_eq!(e, None);
        assert_eq!(g.state(), GateState::Shut(Shut::PositionError(0.003)));
        // Without the limit the same dose passes: the limit is what shut it.
        let mut g = Gate::new(GateParams::default());
        for k in 0..100 {
            g.update(k as f64 * 0.002, &dosed(90.0));
        }
        assert!(g.is_open());
    }
}
