//! What a run records each tick and how it is scored.

use super::*;
use crate::head_drive::Lag;
use mocomp_control::{Event, Mode};
use mocomp_geom::nalgebra::Vector3;
use mocomp_session::PulseAt;

/// One tick of one controller's run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Record {
    /// Time since the controller started, s.
    pub t: f64,
    /// The paper's d, with translation in mm.
    pub d: f64,
    /// Translation error of E2_T_E1, m.
    pub translation_m: f64,
    /// Rotation error of E2_T_E1, rad.
    pub rotation_rad: f64,
    /// The head's true speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// Age of the newest tracker sample the controller used, s (NaN before the first).
    pub sample_age_s: f64,
    /// Time from the newest sample to when the command takes effect, as the controller
    /// predicted (mocomp) or as built into the pipeline (paper), s.
    pub horizon_s: f64,
    /// The controller's mode (paper: always tracking).
    pub mode: Mode,
    /// A safety event in this tick.
    pub event: Option<Event>,
    /// The true coil's signed distance to the head model, m (negative: inside the head).
    pub coil_clearance_m: f64,
    /// The force the true coil presses on the scalp with (the contact law's springs), N.
    pub contact_force_n: f64,
    /// The drift monitor's verdict when it changed this tick.
    pub drift: Option<mocomp_session::Drift>,
    /// The target selected (its index in the session's plan; 0 without one).
    pub target: usize,
    /// The true coil against the selected target on the true head at the cycle's time, m and
    /// rad (the truth the gate's measured error estimates).
    pub target_error: (f64, f64),
    /// The measured error the gate judged, m and rad (NaN without a head estimate).
    pub measured_error: (f64, f64),
    /// The gate after this tick's cycle.
    pub gate_open: bool,
    /// The coil the cycle's command aimed for (the goal on the head it predicted), in the loop's
    /// base frame, m, and the run time it was for, s. `None` without a prediction, or while not
    /// tracking.
    pub aimed_coil: Option<(f64, Vector3<f64>)>,
    /// The coil's goal on the true head at this tick, through the loop's own calibration, m.
    pub goal_coil: Vector3<f64>,
    /// The coil where the arm's joints put it at this tick, through the loop's own calibration,
    /// m.
    pub model_coil: Vector3<f64>,
    /// The prediction's share of the coil's error at this tick: the coil aimed for this time
    /// against the goal on the true head then, m (NaN where no command aimed for it).
    pub prediction_m: f64,
    /// The execution's share: the coil against the one aimed for this time, m (NaN likewise).
    pub execution_m: f64,
    /// How far the safety filter backed this tick's command off along the approach axis (the
    /// standoff it asked for, and this cycle's move back), m: part of the execution's share,
    /// on purpose.
    pub standoff_m: f64,
    /// The dose the true coil gives at the selected target, % of the planned (NaN without a
    /// coil model).
    pub dose_pct: f64,
}

/// A pulse the session logged, with the truth at its time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoggedPulse {
    /// As logged (its time on the run's clock, from the run's start).
    pub pulse: PulseAt,
    /// The true coil against the target then, m and rad.
    pub truth: (f64, f64),
    /// Given by hand (not through the gate).
    pub by_hand: bool,
    /// With a coil model: the dose the true coil gave the target, % of the planned (NaN
    /// without).
    pub dose_pct: f64,
}

/// Summary statistics of a series.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Stats {
    /// Root mean square.
    pub rms: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Maximum.
    pub max: f64,
}

impl Stats {
    /// Of `v` (NaN-free).
    pub fn of(v: &[f64]) -> Self {
        if v.is_empty() {
            return Self {
                rms: f64::NAN,
                p95: f64::NAN,
                max: f64::NAN,
            };
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
        let p95 = s[((s.len() - 1) as f64 * 0.95).round() as usize];
        Self {
            rms,
            p95,
            max: s[s.len() - 1],
        }
    }
}

/// One controller's result.
#[derive(Debug, Clone)]
pub struct Run {
    /// Which controller.
    pub controller: Controller,
    /// Every tick.
    pub records: Vec<Record>,
    /// d (translation in mm).
    pub d: Stats,
    /// Translation error, mm.
    pub translation_mm: Stats,
    /// Rotation error, degrees.
    pub rotation_deg: Stats,
    /// The true coil's least distance to the head model over the run, m (negative: inside).
    pub min_clearance_m: f64,
    /// Time the true coil spent inside the head model, s.
    pub inside_head_s: f64,
    /// The contact force, N.
    pub contact_force_n: Stats,
    /// With a tracker bump: how long after it the drift monitor called the calibration
    /// invalid, s (`None`: no bump, or never).
    pub bump_detected_after_s: Option<f64>,
    /// With a session: every pulse logged, in order.
    pub pulses: Vec<LoggedPulse>,
    /// With a session: the stimulator's gated tries the shut gate withheld.
    pub withheld_pulses: usize,
    /// Where the head robot could not follow the head's trace within its joint limits (it
    /// lagged, and caught up as soon as it could); the score is of the head it played.
    pub head_lags: Vec<Lag>,
    /// The prediction's share of the coil's error, mm, over the ticks a tracking command aimed
    /// for ([`Record::prediction_m`]).
    pub prediction_mm: Stats,
    /// The execution's share, mm, over the same ticks ([`Record::execution_m`]).
    pub execution_mm: Stats,
    /// With a coil model: the dose's error against the planned, |dose − planned| in % of the
    /// planned, over the ticks ([`Record::dose_pct`]).
    pub dose_error_pct: Option<Stats>,
}

impl Run {
    pub(super) fn new(controller: Controller, mut records: Vec<Record>, period_s: f64) -> Self {
        split_errors(&mut records, period_s);
        let col = |f: &dyn Fn(&Record) -> f64| records.iter().map(f).collect::<Vec<f64>>();
        let finite = |f: &dyn Fn(&Record) -> f64| {
            records
                .iter()
                .map(f)
                .filter(|x| x.is_finite())
                .collect::<Vec<f64>>()
        };
        let dose = finite(&|r| (r.dose_pct - 100.0).abs());
        Self {
            dose_error_pct: (!dose.is_empty()).then(|| Stats::of(&dose)),
            prediction_mm: Stats::of(&finite(&|r| r.prediction_m * 1e3)),
            execution_mm: Stats::of(&finite(&|r| r.execution_m * 1e3)),
            min_clearance_m: records
                .iter()
                .map(|r| r.coil_clearance_m)
                .fold(f64::INFINITY, f64::min),
            inside_head_s: records.iter().filter(|r| r.coil_clearance_m < 0.0).count() as f64
                * period_s,
            controller,
            d: Stats::of(&col(&|r| r.d)),
            translation_mm: Stats::of(&col(&|r| r.translation_m * 1e3)),
            rotation_deg: Stats::of(&col(&|r| r.rotation_rad.to_degrees())),
            contact_force_n: Stats::of(&col(&|r| r.contact_force_n)),
            bump_detected_after_s: None,
            pulses: Vec::new(),
            withheld_pulses: 0,
            head_lags: Vec::new(),
            records,
        }
    }
}

/// Fills each tick's prediction and execution shares ([`crate::split`]).
pub(super) fn split_errors(records: &mut [Record], period_s: f64) {
    let ticks: Vec<crate::split::Tick> = records
        .iter()
        .map(|r| crate::split::Tick {
            aimed: r.aimed_coil,
            goal: r.goal_coil,
            model: r.model_coil,
        })
        .collect();
    for (r, share) in records
        .iter_mut()
        .zip(crate::split::shares(&ticks, period_s))
    {
        (r.prediction_m, r.execution_m) = share.unwrap_or((f64::NAN, f64::NAN));
    }
}
