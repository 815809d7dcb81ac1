//! What one cycle did, for the log: a `Copy` record the caller queues for a logger, so the cycle
//! itself logs nothing.

use super::{Event, Mode};
use mocomp_geom::nalgebra::Isometry3;

/// One cycle, for the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleRecord {
    /// Loop time, s.
    pub t: f64,
    /// The mode after this cycle.
    pub mode: Mode,
    /// The event of this cycle.
    pub event: Option<Event>,
    /// Age of the newest accepted tracker sample, s (NaN before the first).
    pub sample_age_s: f64,
    /// Prediction horizon from the newest sample, s (0 without prediction).
    pub horizon_s: f64,
    /// Estimated command delay (send → acknowledged in the robot's state), s.
    pub command_delay_s: f64,
    /// Joints commanded: the loop's command, within its limits and the safety filter's
    /// clearance.
    pub q_command: [f64; 6],
    /// The servo setpoint sent for it: the command plus its lead (`[loop] catch_up_lead`).
    pub q_setpoint: [f64; 6],
    /// Joints measured.
    pub q_actual: [f64; 6],
    /// Joint speeds measured, rad/s.
    pub qd_actual: [f64; 6],
    /// The goal this cycle, `head_from_coil` (the selected target's).
    pub head_from_coil_goal: Isometry3<f64>,
    /// The goal flange pose computed this cycle, if any.
    pub goal: Option<Isometry3<f64>>,
    /// Estimated head speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// While approaching: arc length travelled and the path's length, m.
    pub path: Option<(f64, f64)>,
    /// The standoff along the approach axis the goal was backed off by, m.
    pub standoff_m: f64,
    /// How far the safety filter moved this cycle's command back along the approach axis, m.
    pub filtered_m: f64,
    /// The commanded coil's clearance from the head predicted for the time it acts, m (NaN
    /// without a head estimate; exact below 26.8 mm, what a scalp's sampled clearance knows
    /// exactly, and at least that otherwise).
    pub clearance_m: f64,
    /// The clearance the filter required this cycle, m.
    pub required_m: f64,
    /// The loop coasts on the prediction through a tracker dropout.
    pub coasting: bool,
    /// The measured flange's distance from the goal for the head as estimated now (the state's
    /// time), m and rad: the deviation a live system can report. NaN without a head estimate.
    pub deviation: (f64, f64),
    /// The measured coil's distance from the goal's coil pose for the head as estimated now, m
    /// and rad: what the on-target gate judges (the flange's [`Self::deviation`] differs by the
    /// angle error times the coil's offset from the flange). NaN without a head estimate.
    pub coil_error: (f64, f64),
    /// The measured coil in the head marker's frame (`head_from_coil`) for the head as
    /// estimated now: where a pulse at this cycle lands (the session's record). `None` without
    /// a head estimate.
    pub coil_now: Option<Isometry3<f64>>,
    /// The head marker now (`tracker_from_head` estimated for the cycle's time), when known:
    /// what teaching the goal while the loop runs averages.
    pub head_now: Option<Isometry3<f64>>,
    /// The head predicted for the time this cycle's command acts, and that time (s, the loop's
    /// clock): what the prediction's share of the error is measured on. `None` without a
    /// prediction.
    pub head_at_target: Option<(f64, Isometry3<f64>)>,
    /// The filtered contact force's magnitude, N (NaN without `force_sensing`).
    pub contact_force_n: f64,
    /// The filtered force pushing the coil out along its axis, N (NaN without `force_sensing`).
    pub contact_axial_n: f64,
    /// How far contact mode presses the coil in from its goal along the axis, m.
    pub press_m: f64,
    /// Compute time of the cycle, ns (filled by the caller that owns a clock for it).
    pub compute_ns: u64,
    /// The controller's time of the robot state this cycle answered, s (NaN without one): a
    /// gap of more than a period between cycles is a controller cycle the loop did not answer,
    /// whatever the loop's own clock says of when it ran.
    pub robot_s: f64,
    /// The dose the measured coil ([`Self::coil_now`]) gives at the goal's brain target, V/m,
    /// and as % of the goal's planned dose (NaN without a coil model, a plan for the goal, or a
    /// head estimate; filled by the caller that owns a dose meter).
    pub dose_v_per_m: f64,
    /// See [`Self::dose_v_per_m`].
    pub dose_pct: f64,
}

impl CycleRecord {
    /// A record of a cycle at `t` in `mode` that commanded `q_command`, with nothing else known
    /// yet (NaN, none, zero).
    pub fn new(t: f64, mode: Mode, q_command: [f64; 6]) -> Self {
        Self {
            t,
            mode,
            event: None,
            sample_age_s: f64::NAN,
            horizon_s: 0.0,
            command_delay_s: f64::NAN,
            q_command,
            q_setpoint: q_command,
            q_actual: [f64::NAN; 6],
            qd_actual: [f64::NAN; 6],
            head_from_coil_goal: Isometry3::identity(),
            goal: None,
            head_speed: (0.0, 0.0),
            path: None,
            standoff_m: 0.0,
            filtered_m: 0.0,
            clearance_m: f64::NAN,
            required_m: f64::NAN,
            coasting: false,
            deviation: (f64::NAN, f64::NAN),
            coil_error: (f64::NAN, f64::NAN),
            coil_now: None,
            head_now: None,
            head_at_target: None,
            contact_force_n: f64::NAN,
            contact_axial_n: f64::NAN,
            press_m: 0.0,
            compute_ns: 0,
            robot_s: f64::NAN,
            dose_v_per_m: f64::NAN,
            dose_pct: f64::NAN,
        }
    }
}
