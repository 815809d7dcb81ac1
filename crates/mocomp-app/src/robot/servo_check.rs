//! `mocomp robot stream`: a servo streaming check against any UR controller (a real one, or a
//! simulated one): a smooth joint trajectory with servoj at the controller's rate, with the
//! tracking error and the loop's timing measured.

use crate::{AppError, Context};
use mocomp_geom::{Clock, MonotonicClock, translation_error};
use mocomp_kin::{Arm, Model};
use mocomp_ur::{Robot, ServoParams, UrConfig, UrRobot};
use serde::Serialize;
use std::collections::VecDeque;
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

/// How much trajectory time one command may advance over the one before, per second since that
/// one left: the trajectory catches up after a stall at half again its own speed, far below the
/// controller's limit.
const CATCH_UP: f64 = 1.5;

/// The next command's trajectory time after `previous`, when the controller's next cycle is at
/// `controller_next` (both from the stream's start) and `since` seconds have passed since the
/// previous command left: the controller's, or at most [`CATCH_UP`] times the time since (a
/// period at least) on where a stall left the trajectory behind it.
fn trajectory_time(previous: f64, controller_next: f64, since: f64, period: f64) -> f64 {
    controller_next.min(previous + CATCH_UP * since.max(period))
}

/// Servos a smooth joint trajectory (joints 1 and 6 out by up to `amplitude` and back) on the
/// controller at `host` at its rate, from this thread in real time, and measures the tracking
/// error and the loop timing. `notice` is told of a real-time refusal.
///
/// The trajectory runs on the controller's clock, the one it judges each setpoint's speed by: a
/// real controller's keeps to the wall clock, but a simulator that a busy machine stopped gives
/// cycles up and falls behind, and a target taken at the wall clock would then jump by what it
/// gave up (a protective stop for a setpoint too fast).
///
/// Each command's trajectory time also advances over the one before by at most [`CATCH_UP`]
/// times the time since that one left. The controller judges a setpoint's step over its own time since the last one arrived,
/// and this client cannot know when that was: a command computed from a stale state (a receive
/// thread the host left unscheduled) or held between its computing and its sending arrives late,
/// and the next, from a fresh state, would step by the whole stall within one cycle (C204A3 at
/// the trajectory's peak speed). Bounded, a stall slows the trajectory for a moment instead; the
/// errors are measured against the command the state acknowledges, so that moment is not
/// counted as the arm's error.
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
    let mut errors = Errors::with_capacity(n);
    let mut tau = 0.0f64;
    let start = clock.now_s();
    let mut left = start;
    let t0 = Instant::now();
    let mut k = 0usize;
    while k < n {
        // Absolute deadlines: a late wake-up skips those it missed rather than bursting.
        mocomp_rt::sleep_until(t0 + Duration::from_secs_f64(k as f64 * period));
        let t = clock.now_s() - start;
        let next = (k.max((t / period).floor() as usize) + 1).min(n);
        errors.skipped += next - k - 1;
        k = next;
        let Some(s) = robot.state() else {
            errors.skipped += 1;
            continue;
        };
        if let Some(f) = s.fault() {
            errors.fault = Some((t, f.to_string()));
            break;
        }
        let answered = errors.acknowledged(s.acked_seq, s.received_s);
        let tc = s.controller_s - c0 + period; // the controller's next cycle
        let sent = clock.now_s();
        tau = trajectory_time(tau, tc, sent - left, period);
        let seq = robot.servo(&target(tau), &params).what(|| "servoj")?;
        // Once the call returned the command has left, however late the host let it go.
        left = clock.now_s();
        errors.sent(seq, tau, sent, left);
        if let Some(ts) = answered.filter(|&ts| ts > 1.0) {
            // Error against the target the controller servos to (includes the servo's lag) and
            // against the target one lookahead earlier (the lag a servo with lookahead shows).
            let now_t = target(ts);
            let err =
                |q: &[f64; 6]| (0..6).fold(0.0f64, |m, j| m.max((s.actual_q[j] - q[j]).abs()));
            errors.joint_err.push(err(&now_t));
            errors.comp_err.push(err(&target(ts - a.lookahead)));
            errors
                .tcp_err
                .push(translation_error(&arm.fk(&now_t), &s.base_from_tcp) * 1e3);
        }
    }
    robot.stop(4.0).what(|| "stopping the robot")?;
    let expected_lag_rad =
        a.lookahead * (0..n).fold(0.0f64, |m, k| m.max(target_speed(k as f64 * period).abs()));
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
    /// (sequence, sent at) of each command not yet acknowledged.
    pending: VecDeque<(i32, f64)>,
    /// (sequence, trajectory time) of each command not yet overtaken by a newer acknowledged
    /// one.
    commanded: VecDeque<(i32, f64)>,
    /// When the last command was sent, s.
    last_send: Option<f64>,
}

impl Errors {
    fn with_capacity(n: usize) -> Self {
        Self {
            periods: Vec::with_capacity(n),
            acks: Vec::with_capacity(n),
            calls: Vec::with_capacity(n),
            joint_err: Vec::with_capacity(n),
            comp_err: Vec::with_capacity(n),
            tcp_err: Vec::with_capacity(n),
            skipped: 0,
            fault: None,
            pending: VecDeque::new(),
            commanded: VecDeque::new(),
            last_send: None,
        }
    }

    /// Takes in a state that acknowledges command `acked` and was received at `received_s`:
    /// the latency of each command it acknowledges first, and the trajectory time of the command
    /// it answers (the arm's current target), if this client sent it.
    fn acknowledged(&mut self, acked: i32, received_s: f64) -> Option<f64> {
        while let Some(&(seq, sent)) = self.pending.front() {
            if acked.wrapping_sub(seq) < 0 {
                break;
            }
            self.acks.push((received_s - sent) * 1e3);
            self.pending.pop_front();
        }
        while self
            .commanded
            .get(1)
            .is_some_and(|&(seq, _)| acked.wrapping_sub(seq) >= 0)
        {
            self.commanded.pop_front();
        }
        self.commanded
            .front()
            .filter(|&&(seq, _)| acked.wrapping_sub(seq) >= 0)
            .map(|&(_, t)| t)
    }

    /// Notes command `seq` for trajectory time `tau`, its call begun at `sent` and returned at
    /// `returned`, s.
    fn sent(&mut self, seq: i32, tau: f64, sent: f64, returned: f64) {
        self.calls.push((returned - sent) * 1e6);
        self.pending.push_back((seq, sent));
        self.commanded.push_back((seq, tau));
        if let Some(last) = self.last_send {
            self.periods.push((sent - last) * 1e3);
        }
        self.last_send = Some(sent);
    }

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

#[cfg(test)]
mod tests {
    use super::*;

    const P: f64 = 0.002;

    /// Trajectory times for commands leaving at `left` (s) with the controller's next cycle at
    /// `tc`, each pair in turn.
    fn taus(commands: &[(f64, f64)]) -> Vec<f64> {
        let (mut tau, mut last) = (0.0, 0.0);
        commands
            .iter()
            .map(|&(left, tc)| {
                tau = trajectory_time(tau, tc, left - last, P);
                last = left;
                tau
            })
            .collect()
    }

    #[test]
    fn a_stale_state_slows_the_trajectory_and_never_steps_it_by_the_stall() {
        // A command each cycle; from 100 ms the states stall 30 ms (the client reads the same
        // controller time), then they are fresh again.
        let mut c: Vec<(f64, f64)> = (1..=50).map(|k| (k as f64 * P, k as f64 * P)).collect();
        c.extend((51..=65).map(|k| (k as f64 * P, 50.0 * P)));
        c.extend((66..=200).map(|k| (k as f64 * P, k as f64 * P)));
        let taus = taus(&c);
        let steps: Vec<f64> = taus.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            steps.iter().all(|d| *d >= 0.0 && *d <= 1.5 * P + 1e-12),
            "{steps:?}"
        );
        // In step with the controller until the stall, then caught up again, never ahead.
        assert!((taus[49] - 0.1).abs() < 1e-12);
        assert!((taus.last().unwrap() - 0.4).abs() < 1e-12, "{taus:?}");
        assert!(taus.iter().zip(&c).all(|(t, (_, tc))| *t <= tc + 1e-12));
    }

    #[test]
    fn a_command_held_before_it_left_is_not_overtaken_by_a_jump() {
        // The command computed at 100 ms leaves at 125 ms (the host held this thread); the
        // next leaves 2 ms later from a fresh state. Without the bound it would step 26 ms of
        // trajectory within the controller's one cycle.
        let taus = taus(&[
            (0.098, 0.098),
            (0.100, 0.100),
            (0.125, 0.100),
            (0.127, 0.127),
        ]);
        assert!((taus[2] - 0.100).abs() < 1e-12);
        assert!(taus[3] - taus[2] <= 1.5 * P + 1e-12, "{taus:?}");
    }

    #[test]
    fn a_client_slower_than_the_controller_keeps_its_pace() {
        // Commands every 6 ms (two of three deadlines skipped): each steps the controller's 6 ms.
        let c: Vec<(f64, f64)> = (1..=100)
            .map(|k| (k as f64 * 0.006, k as f64 * 0.006))
            .collect();
        let taus = taus(&c);
        assert!(
            taus.iter()
                .zip(&c)
                .all(|(t, (_, tc))| (t - tc).abs() < 1e-12)
        );
    }

    #[test]
    fn errors_are_against_the_command_the_state_answers() {
        let mut e = Errors::with_capacity(8);
        assert_eq!(e.acknowledged(0, 0.0), None, "nothing sent yet");
        e.sent(1, 0.10, 1.000, 1.0001);
        e.sent(2, 0.11, 1.002, 1.0021);
        e.sent(3, 0.12, 1.004, 1.0041);
        // A state from before this client's first command answers none of them.
        assert_eq!(e.acknowledged(0, 1.001), None);
        assert_eq!(e.acknowledged(2, 1.005), Some(0.11));
        assert_eq!(e.acks.len(), 2);
        assert!((e.acks[0] - 5.0).abs() < 1e-9 && (e.acks[1] - 3.0).abs() < 1e-9);
        // The same answer again, then the newest.
        assert_eq!(e.acknowledged(2, 1.006), Some(0.11));
        assert_eq!(e.acknowledged(3, 1.007), Some(0.12));
        assert_eq!(e.acks.len(), 3);
        assert_eq!(e.periods.len(), 2);
        // Sequence numbers wrap.
        let mut w = Errors::with_capacity(2);
        w.sent(i32::MAX, 1.0, 0.0, 0.0);
        w.sent(i32::MIN, 2.0, 0.002, 0.002);
        assert_eq!(w.acknowledged(i32::MIN, 0.003), Some(2.0));
    }
}
