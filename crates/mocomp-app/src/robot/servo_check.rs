//! `mocomp robot stream`: a servo streaming check against any UR controller (a real one, or a
//! simulated one): a smooth joint trajectory with servoj at the controller's rate, with the
//! tracking error and the loop's timing measured.

use crate::{AppError, Context};
use mocomp_geom::{Clock, MonotonicClock, translation_error};
use mocomp_kin::{Arm, Model};
use mocomp_ur::{Robot, ServoParams, UrConfig, UrRobot};
use serde::Serialize;
use std::io::Write;
use std::net::IpAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Connects mocomp's client to the controller at `host`.
pub fn connect(host: IpAddr) -> Result<UrRobot, AppError> {
    UrRobot::connect(UrConfig::new(host), Arc::new(MonotonicClock::new()))
        .what(|| format!("connecting to the UR controller at {host}"))
}

/// What `mocomp robot stream` streams.
#[derive(Debug, Clone, Copy)]
pub struct StreamOptions {
    /// Seconds to stream.
    pub seconds: f64,
    /// Amplitude of the joint motion, rad.
    pub amplitude: f64,
    /// Frequency of the joint motion, Hz.
    pub frequency: f64,
    /// servoj lookahead, s.
    pub lookahead: f64,
    /// servoj gain.
    pub gain: f64,
}

/// What the stream measured (`mocomp robot stream --json`).
#[derive(Serialize, Debug, Clone)]
pub struct StreamReport {
    /// The robot model.
    pub model: String,
    /// The controller's version.
    pub controller: String,
    /// The controller's rate.
    pub rate_hz: f64,
    /// Commands sent.
    pub cycles: usize,
    /// Streamed for.
    pub seconds: f64,
    /// Command period, median.
    pub period_median_ms: f64,
    /// Command period, 99th percentile.
    pub period_p99_ms: f64,
    /// Command period, largest.
    pub period_max_ms: f64,
    /// Periods without a command.
    pub missed_cycles: usize,
    /// Deadlines passed without a command (woken too late for them, or no state yet): with
    /// `cycles`, every deadline of the run.
    pub skipped_deadlines: usize,
    /// Time in the servo call, median.
    pub servo_call_median_us: f64,
    /// The same, 99th percentile.
    pub servo_call_p99_us: f64,
    /// From sending a command to its acknowledgement in the state, median.
    pub ack_latency_median_ms: f64,
    /// The same, 99th percentile.
    pub ack_latency_p99_ms: f64,
    /// Largest joint error against the current target.
    pub tracking_joint_max_rad: f64,
    /// The same, RMS.
    pub tracking_joint_rms_rad: f64,
    /// Largest TCP error against the current target.
    pub tracking_tcp_max_mm: f64,
    /// The same, RMS.
    pub tracking_tcp_rms_mm: f64,
    /// The servo lag expected: lookahead × the largest joint speed.
    pub expected_lag_rad: f64,
    /// Largest joint error against the target one lookahead earlier.
    pub lag_compensated_joint_max_rad: f64,
    /// The same, RMS.
    pub lag_compensated_joint_rms_rad: f64,
    /// Whether the stream ended in a fault.
    pub protective_stop: bool,
    /// When and why it did.
    pub fault: Option<(f64, String)>,
    /// The real-time scheduling the stream got.
    pub realtime: String,
}

impl std::fmt::Display for StreamReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self;
        writeln!(
            f,
            "{} ({} at {:.0} Hz): {} cycles in {} s\n  period median {:.3} ms, p99 {:.3} ms, max {:.3} ms, missed {}\n  servo call median {:.1} us, p99 {:.1} us\n  command → acknowledged in state: median {:.2} ms, p99 {:.2} ms\n  tracking vs current target: joint max {:.4} rad (rms {:.4}; servo lag expected ≈ lookahead × speed = {:.4}), TCP max {:.2} mm (rms {:.2})\n  vs target one lookahead earlier: joint max {:.5} rad",
            r.model,
            r.controller,
            r.rate_hz,
            r.cycles,
            r.seconds,
            r.period_median_ms,
            r.period_p99_ms,
            r.period_max_ms,
            r.missed_cycles,
            r.servo_call_median_us,
            r.servo_call_p99_us,
            r.ack_latency_median_ms,
            r.ack_latency_p99_ms,
            r.tracking_joint_max_rad,
            r.tracking_joint_rms_rad,
            r.expected_lag_rad,
            r.tracking_tcp_max_mm,
            r.tracking_tcp_rms_mm,
            r.lag_compensated_joint_max_rad,
        )
    }
}

/// A controller's state as mocomp's client reads it (`mocomp robot state`).
#[derive(Debug, Clone, Serialize)]
pub struct StateReport {
    /// The controller's clock, s.
    pub controller_s: f64,
    /// Joint angles, rad.
    pub actual_q: [f64; 6],
    /// The TCP as a UR pose vector (m, rotation vector).
    pub tcp_pose: [f64; 6],
    /// Robot mode.
    pub robot_mode: String,
    /// Safety mode.
    pub safety_mode: String,
    /// Program state.
    pub runtime_state: String,
    /// The fault it reports, if any.
    pub fault: Option<String>,
    /// `actual_TCP_force`: N and N·m, base frame.
    pub tcp_force: [f64; 6],
    #[serde(skip)]
    head: String,
}

impl StateReport {
    /// Connects to the controller at `host`, starts the control program and reads its state.
    pub fn read(host: IpAddr) -> Result<Self, AppError> {
        let robot = connect(host)?;
        let Some(s) = robot.state() else {
            refuse!("no state received from {host}");
        };
        Ok(Self {
            controller_s: s.controller_s,
            actual_q: s.actual_q,
            tcp_pose: mocomp_geom::ur_pose_from_iso(&s.base_from_tcp),
            robot_mode: s.robot_mode.to_string(),
            safety_mode: s.safety_mode.to_string(),
            runtime_state: s.runtime_state.to_string(),
            fault: s.fault().map(|f| f.to_string()),
            tcp_force: s.tcp_force,
            head: format!("controller {} at {host}", robot.controller_version()),
        })
    }
}

impl std::fmt::Display for StateReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{}: {} / {} / {}; q = {:?} rad; TCP = {:?}; TCP force = {:?} N, N·m (base frame); fault: {}",
            self.head,
            self.robot_mode,
            self.safety_mode,
            self.runtime_state,
            self.actual_q,
            self.tcp_pose,
            self.tcp_force,
            self.fault.as_deref().unwrap_or("none")
        )
    }
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((p / 100.0) * (v.len() - 1) as f64).round() as usize]
}

/// Servos a smooth joint trajectory (joints 1 and 6 out by up to `amplitude` and back) on the
/// controller at `host` at its rate, from this thread in real time, and measures the tracking
/// error and the loop timing. `notice` is told of a real-time refusal.
///
/// The trajectory runs on the controller's clock, the one it judges each setpoint's speed by: a
/// real controller's keeps to the wall clock, but a simulator that a busy machine stopped gives
/// cycles up and falls behind, and a target taken at the wall clock would then jump by what it
/// gave up (a protective stop for a setpoint too fast).
pub fn stream(
    model: Model,
    host: IpAddr,
    a: StreamOptions,
    notice: &mut dyn Write,
) -> Result<StreamReport, AppError> {
    // The streaming thread (and the client's receive thread, started from it) in real time.
    let rt = mocomp_rt::RtConfig::default();
    let (realtime, _cpu_latency) = mocomp_rt::apply(&rt, rt.priority);
    if let Some(w) = realtime.warning() {
        writeln!(notice, "warning: {w}").what(|| "writing the progress")?;
    }
    let clock = MonotonicClock::new();
    let mut robot = connect(host)?;
    let period = robot.period_s();
    let Some(s0) = robot.state() else {
        refuse!("no state from {host}");
    };
    let arm = Arm::new(model);
    let q0 = s0.actual_q;
    let c0 = s0.controller_s;
    let params = ServoParams {
        time_s: period,
        lookahead_s: a.lookahead,
        gain: a.gain,
    };
    params
        .validate()
        .map_err(|e| AppError::Config(e.to_string()))?;
    let w = std::f64::consts::TAU * a.frequency;
    let target = |t: f64| {
        let mut q = q0;
        let d = a.amplitude * 0.5 * (1.0 - (w * t).cos());
        q[0] += d;
        q[5] -= d;
        q
    };
    let target_speed = |t: f64| a.amplitude * 0.5 * w * (w * t).sin();
    let n = (a.seconds / period).round() as usize;
    let mut periods = Vec::with_capacity(n);
    let mut acks = Vec::with_capacity(n);
    let mut calls = Vec::with_capacity(n);
    let mut joint_err = Vec::with_capacity(n);
    let mut comp_err = Vec::with_capacity(n);
    let mut tcp_err = Vec::with_capacity(n);
    let mut pending: std::collections::VecDeque<(i32, f64)> = std::collections::VecDeque::new();
    let start = clock.now_s();
    let t0 = Instant::now();
    let mut last_send = f64::NAN;
    let mut fault = None;
    let mut k = 0usize;
    let mut skipped = 0usize;
    while k < n {
        // Absolute deadlines: a late wake-up skips those it missed rather than bursting.
        mocomp_rt::sleep_until(t0 + Duration::from_secs_f64(k as f64 * period));
        let t = clock.now_s() - start;
        let next = (k.max((t / period).floor() as usize) + 1).min(n);
        skipped += next - k - 1;
        k = next;
        let Some(s) = robot.state() else {
            skipped += 1;
            continue;
        };
        if let Some(f) = s.fault() {
            fault = Some((t, f.to_string()));
            break;
        }
        while let Some(&(seq, sent)) = pending.front() {
            if s.acked_seq.wrapping_sub(seq) >= 0 {
                acks.push((s.received_s - sent) * 1e3);
                pending.pop_front();
            } else {
                break;
            }
        }
        let tc = s.controller_s - c0 + period; // the controller's next cycle
        let q = target(tc);
        let sent = clock.now_s();
        let seq = robot.servo(&q, &params).what(|| "servoj")?;
        calls.push((clock.now_s() - sent) * 1e6);
        pending.push_back((seq, sent));
        if !last_send.is_nan() {
            periods.push((sent - last_send) * 1e3);
        }
        last_send = sent;
        if tc > 1.0 {
            // Error against the target commanded at the state's time (includes the servo's
            // lag) and against the target one lookahead earlier (the lag a servo with lookahead
            // shows). The state is the controller's newest, at its `controller_s`.
            let ts = s.controller_s - c0;
            let now_t = target(ts);
            let e = (0..6).fold(0.0f64, |m, j| m.max((s.actual_q[j] - now_t[j]).abs()));
            joint_err.push(e);
            let lagged = target(ts - a.lookahead);
            comp_err.push((0..6).fold(0.0f64, |m, j| m.max((s.actual_q[j] - lagged[j]).abs())));
            tcp_err.push(translation_error(&arm.fk(&now_t), &s.base_from_tcp) * 1e3);
        }
    }
    robot.stop(4.0).what(|| "stopping the robot")?;
    let expected_lag_rad =
        a.lookahead * (0..n).fold(0.0f64, |m, k| m.max(target_speed(k as f64 * period).abs()));
    let errors = Errors {
        periods,
        acks,
        calls,
        joint_err,
        comp_err,
        tcp_err,
        skipped,
        fault,
    };
    Ok(errors.report(
        model,
        robot.controller_version().to_string(),
        period,
        &a,
        expected_lag_rad,
        realtime.describe(),
    ))
}

/// What a stream measured, each a sample per cycle.
struct Errors {
    /// Between servo calls, ms.
    periods: Vec<f64>,
    /// From a command to the controller's acknowledgement, ms.
    acks: Vec<f64>,
    /// A servo call's own time, µs.
    calls: Vec<f64>,
    /// The largest joint's error against the target at the state's time, rad.
    joint_err: Vec<f64>,
    /// The same against the target one lookahead earlier, rad.
    comp_err: Vec<f64>,
    /// The TCP's error, mm.
    tcp_err: Vec<f64>,
    /// Deadlines skipped (a late wake-up, or no state).
    skipped: usize,
    /// When and why the controller stopped the stream, if it did.
    fault: Option<(f64, String)>,
}

impl Errors {
    /// The report of a stream at `period` with options `a`.
    fn report(
        mut self,
        model: Model,
        controller: String,
        period: f64,
        a: &StreamOptions,
        expected_lag_rad: f64,
        realtime: String,
    ) -> StreamReport {
        let missed = self
            .periods
            .iter()
            .filter(|p| **p > 1.5 * period * 1e3)
            .count();
        let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
        let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(*x));
        StreamReport {
            model: model.to_string(),
            controller,
            rate_hz: 1.0 / period,
            cycles: self.periods.len() + 1,
            seconds: a.seconds,
            period_median_ms: percentile(&mut self.periods.clone(), 50.0),
            period_p99_ms: percentile(&mut self.periods.clone(), 99.0),
            period_max_ms: max(&self.periods),
            missed_cycles: missed,
            skipped_deadlines: self.skipped,
            servo_call_median_us: percentile(&mut self.calls.clone(), 50.0),
            servo_call_p99_us: percentile(&mut self.calls, 99.0),
            ack_latency_median_ms: percentile(&mut self.acks.clone(), 50.0),
            ack_latency_p99_ms: percentile(&mut self.acks, 99.0),
            tracking_joint_max_rad: max(&self.joint_err),
            tracking_joint_rms_rad: rms(&self.joint_err),
            tracking_tcp_max_mm: max(&self.tcp_err),
            tracking_tcp_rms_mm: rms(&self.tcp_err),
            expected_lag_rad,
            lag_compensated_joint_max_rad: max(&self.comp_err),
            lag_compensated_joint_rms_rad: rms(&self.comp_err),
            protective_stop: self.fault.is_some(),
            fault: self.fault,
            realtime,
        }
    }
}
