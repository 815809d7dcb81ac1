//! `mocomp ursim` (a simulated controller on a loopback address) and `mocomp robot` (our client
//! against any UR controller: its state, and a servo streaming check with timing figures).

use anyhow::{Context, Result, bail};
use mocomp_geom::{Clock, MonotonicClock, translation_error};
use mocomp_kin::{Arm, Model};
use mocomp_ur::{Robot, ServoParams, UrConfig, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimConfig};
use serde::Serialize;
use std::io::Write;
use std::net::IpAddr;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Starts a real-time simulator of `model` on the standard ports of `host`. It stands for the
/// controller's own computer, so its threads run at `SCHED_FIFO` (the default simulator
/// priority) where the operating system allows: they inherit it from the calling thread, which
/// is left at that priority. A refusal is printed once as a warning.
pub fn start_sim(model: Model, host: IpAddr) -> Result<Sim> {
    let rt = mocomp_rt::RtConfig::default();
    if let Err(e) = mocomp_rt::set_fifo(rt.simulator_priority) {
        eprintln!("warning: the simulated controller runs without real-time scheduling: {e}");
    }
    Sim::start(SimConfig::new(ControllerConfig::new(model), host)).with_context(|| {
        format!(
            "starting the simulated {model} on {host} (each simulator needs its own loopback \
             address: 127.0.0.2, 127.0.0.3, …)"
        )
    })
}

/// `mocomp ursim`: serve until killed (or for `seconds`), printing the controller's events.
pub fn ursim(out: &mut impl Write, model: Model, host: IpAddr, seconds: Option<f64>) -> Result<()> {
    let sim = start_sim(model, host)?;
    let a = sim.addrs();
    let v = sim.with(|c| c.config().version());
    writeln!(
        out,
        "simulated {model} (controller {v}, {:.0} Hz): RTDE {}, dashboard {}, script {} / {} / {}",
        1.0 / sim.with(|c| c.period_s()),
        a.rtde,
        a.dashboard,
        a.primary,
        a.secondary,
        a.realtime
    )?;
    out.flush()?;
    let start = Instant::now();
    let mut seen = 0;
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let (events, total) = sim.with(|c| c.events());
        let new = (total - seen) as usize;
        for e in events.iter().skip(events.len().saturating_sub(new)) {
            writeln!(out, "[{:10.3} s] {}", e.time_s, e.text)?;
        }
        seen = total;
        out.flush()?;
        if seconds.is_some_and(|s| start.elapsed().as_secs_f64() >= s) {
            let st = sim.stats();
            writeln!(
                out,
                "{} cycles, {} inputs, {} outputs ({} skipped), {} bad packages, {} overruns",
                st.ticks, st.inputs, st.outputs, st.outputs_skipped, st.bad_packages, st.overruns
            )?;
            return Ok(());
        }
    }
}

fn connect(host: IpAddr) -> Result<UrRobot> {
    UrRobot::connect(UrConfig::new(host), Arc::new(MonotonicClock::new()))
        .with_context(|| format!("connecting to the UR controller at {host}"))
}

#[derive(Serialize)]
struct StateJson {
    controller_s: f64,
    actual_q: [f64; 6],
    tcp_pose: [f64; 6],
    robot_mode: String,
    safety_mode: String,
    runtime_state: String,
    fault: Option<String>,
}

/// `mocomp robot state`.
pub fn state(out: &mut impl Write, host: IpAddr, json: bool) -> Result<()> {
    let robot = connect(host)?;
    let Some(s) = robot.state() else {
        bail!("no state received from {host}");
    };
    let j = StateJson {
        controller_s: s.controller_s,
        actual_q: s.actual_q,
        tcp_pose: mocomp_geom::ur_pose_from_iso(&s.base_from_tcp),
        robot_mode: s.robot_mode.to_string(),
        safety_mode: s.safety_mode.to_string(),
        runtime_state: s.runtime_state.to_string(),
        fault: s.fault().map(|f| f.to_string()),
    };
    if json {
        writeln!(out, "{}", serde_json::to_string(&j)?)?;
    } else {
        writeln!(
            out,
            "controller {} at {host}: {} / {} / {}; q = {:?} rad; TCP = {:?}; fault: {}",
            robot.controller_version(),
            j.robot_mode,
            j.safety_mode,
            j.runtime_state,
            j.actual_q,
            j.tcp_pose,
            j.fault.as_deref().unwrap_or("none")
        )?;
    }
    Ok(())
}

/// Options of `mocomp robot stream`.
#[derive(Debug, Clone, Copy)]
pub struct StreamArgs {
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

#[derive(Serialize, Debug)]
struct StreamReport {
    model: String,
    controller: String,
    rate_hz: f64,
    cycles: usize,
    seconds: f64,
    period_median_ms: f64,
    period_p99_ms: f64,
    period_max_ms: f64,
    missed_cycles: usize,
    servo_call_median_us: f64,
    servo_call_p99_us: f64,
    ack_latency_median_ms: f64,
    ack_latency_p99_ms: f64,
    tracking_joint_max_rad: f64,
    tracking_joint_rms_rad: f64,
    tracking_tcp_max_mm: f64,
    tracking_tcp_rms_mm: f64,
    expected_lag_rad: f64,
    lag_compensated_joint_max_rad: f64,
    lag_compensated_joint_rms_rad: f64,
    protective_stop: bool,
    realtime: String,
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[((p / 100.0) * (v.len() - 1) as f64).round() as usize]
}

/// `mocomp robot stream`: servo a smooth joint trajectory at the controller rate and report the
/// tracking error and the loop timing.
pub fn stream(
    out: &mut impl Write,
    model: Model,
    host: IpAddr,
    a: StreamArgs,
    json: bool,
) -> Result<()> {
    // The streaming thread (and the client's receive thread, started from it) in real time.
    let rt = mocomp_rt::RtConfig::default();
    let (realtime, _cpu_latency) = mocomp_rt::apply(&rt, rt.priority);
    if let Some(w) = realtime.warning() {
        eprintln!("warning: {w}");
    }
    let clock = MonotonicClock::new();
    let mut robot = connect(host)?;
    let period = robot.period_s();
    let Some(s0) = robot.state() else {
        bail!("no state from {host}");
    };
    let arm = Arm::new(model);
    let q0 = s0.actual_q;
    let params = ServoParams {
        time_s: period,
        lookahead_s: a.lookahead,
        gain: a.gain,
    };
    params.validate()?;
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
    let mut protective = false;
    let mut k = 0usize;
    while k < n {
        // Absolute deadlines; a late wake-up skips the deadlines it missed instead of sending
        // them in a burst, and the target is taken at the real time, so the trajectory the
        // controller sees stays smooth whatever this thread's timing.
        mocomp_rt::sleep_until(t0 + Duration::from_secs_f64(k as f64 * period));
        let t = clock.now_s() - start;
        k = k.max((t / period).floor() as usize) + 1;
        let Some(s) = robot.state() else { continue };
        if let Some(f) = s.fault() {
            protective = true;
            writeln!(out, "stopped at {t:.3} s: {f}")?;
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
        let q = target(t);
        let sent = clock.now_s();
        let seq = robot.servo(&q, &params)?;
        calls.push((clock.now_s() - sent) * 1e6);
        pending.push_back((seq, sent));
        if !last_send.is_nan() {
            periods.push((sent - last_send) * 1e3);
        }
        last_send = sent;
        if t > 1.0 {
            // Error against the target commanded at the state's time (includes the servo's
            // lag) and against the target one lookahead earlier (the lag a servo with lookahead
            // shows). The state is the controller's newest, received at `received_s`.
            let ts = s.received_s - start - period;
            let now_t = target(ts);
            let e = (0..6).fold(0.0f64, |m, j| m.max((s.actual_q[j] - now_t[j]).abs()));
            joint_err.push(e);
            let lagged = target(ts - a.lookahead);
            comp_err.push((0..6).fold(0.0f64, |m, j| m.max((s.actual_q[j] - lagged[j]).abs())));
            tcp_err.push(translation_error(&arm.fk(&now_t), &s.base_from_tcp) * 1e3);
        }
    }
    robot.stop(4.0)?;
    let missed = periods.iter().filter(|p| **p > 1.5 * period * 1e3).count();
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
    let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(*x));
    let report = StreamReport {
        model: model.to_string(),
        controller: robot.controller_version().to_string(),
        rate_hz: 1.0 / period,
        cycles: periods.len() + 1,
        seconds: a.seconds,
        period_median_ms: percentile(&mut periods.clone(), 50.0),
        period_p99_ms: percentile(&mut periods.clone(), 99.0),
        period_max_ms: max(&periods),
        missed_cycles: missed,
        servo_call_median_us: percentile(&mut calls.clone(), 50.0),
        servo_call_p99_us: percentile(&mut calls, 99.0),
        ack_latency_median_ms: percentile(&mut acks.clone(), 50.0),
        ack_latency_p99_ms: percentile(&mut acks, 99.0),
        tracking_joint_max_rad: max(&joint_err),
        tracking_joint_rms_rad: rms(&joint_err),
        tracking_tcp_max_mm: max(&tcp_err),
        tracking_tcp_rms_mm: rms(&tcp_err),
        expected_lag_rad: a.lookahead
            * (0..n).fold(0.0f64, |m, k| m.max(target_speed(k as f64 * period).abs())),
        lag_compensated_joint_max_rad: max(&comp_err),
        lag_compensated_joint_rms_rad: rms(&comp_err),
        protective_stop: protective,
        realtime: realtime.describe(),
    };
    if json {
        writeln!(out, "{}", serde_json::to_string(&report)?)?;
    } else {
        writeln!(
            out,
            "{} ({} at {:.0} Hz): {} cycles in {} s\n  period median {:.3} ms, p99 {:.3} ms, max {:.3} ms, missed {}\n  servo call median {:.1} us, p99 {:.1} us\n  command → acknowledged in state: median {:.2} ms, p99 {:.2} ms\n  tracking vs current target: joint max {:.4} rad (rms {:.4}; servo lag expected ≈ lookahead × speed = {:.4}), TCP max {:.2} mm (rms {:.2})\n  vs target one lookahead earlier: joint max {:.5} rad",
            report.model,
            report.controller,
            report.rate_hz,
            report.cycles,
            report.seconds,
            report.period_median_ms,
            report.period_p99_ms,
            report.period_max_ms,
            report.missed_cycles,
            report.servo_call_median_us,
            report.servo_call_p99_us,
            report.ack_latency_median_ms,
            report.ack_latency_p99_ms,
            report.tracking_joint_max_rad,
            report.tracking_joint_rms_rad,
            report.expected_lag_rad,
            report.tracking_tcp_max_mm,
            report.tracking_tcp_rms_mm,
            report.lag_compensated_joint_max_rad,
        )?;
    }
    if protective {
        bail!("the stream ended in a fault");
    }
    Ok(())
}
