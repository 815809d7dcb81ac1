//! `mocomp robot stream`: the servo streaming check ([`mocomp_app::servo_check`]), printed.

use anyhow::{Result, bail};
use clap::Args;
use mocomp_app::servo_check::{StreamOptions, StreamReport, stream};
use mocomp_kin::Model;
use std::io::Write;
use std::net::IpAddr;

/// Stream a smooth joint trajectory with servoj at the controller rate; report the tracking
/// error and the loop timing. Moves joints 1 and 6 by up to --amplitude: clear the space.
#[derive(Debug, Clone, Args)]
pub struct StreamCmd {
    /// Controller address.
    #[arg(long)]
    host: IpAddr,
    /// Robot model (for the TCP error).
    #[arg(long, value_parser = crate::args::model)]
    model: Model,
    /// Start a simulated controller of --model at --host first.
    #[arg(long)]
    ursim: bool,
    /// Seconds to stream.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Joint motion amplitude, radians.
    #[arg(long, default_value_t = 0.2)]
    amplitude: f64,
    /// Joint motion frequency, Hz.
    #[arg(long, default_value_t = 0.5)]
    frequency: f64,
    /// servoj lookahead time, seconds [0.03, 0.2].
    #[arg(long, default_value_t = 0.05)]
    lookahead: f64,
    /// servoj gain [100, 2000].
    #[arg(long, default_value_t = 1000.0)]
    gain: f64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

impl StreamCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        for (name, v, lo, hi) in [
            ("--seconds", self.seconds, 0.1, 3600.0),
            ("--amplitude", self.amplitude, 0.0, 1.0),
            ("--frequency", self.frequency, 0.01, 5.0),
        ] {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(
                    crate::UsageError(format!("{name} {v}: must be in [{lo}, {hi}]")).into(),
                );
            }
        }
        let _sim = self
            .ursim
            .then(|| crate::ursim::start(self.model, self.host, &Default::default()))
            .transpose()?;
        let o = StreamOptions {
            seconds: self.seconds,
            amplitude: self.amplitude,
            frequency: self.frequency,
            lookahead: self.lookahead,
            gain: self.gain,
        };
        let r = stream(self.model, self.host, o, &mut std::io::stderr())?;
        print(out, &r, self.json)
    }
}

fn print(out: &mut dyn Write, r: &StreamReport, json: bool) -> Result<()> {
    if json {
        writeln!(out, "{}", serde_json::to_string(r)?)?;
    } else {
        writeln!(
            out,
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
        )?;
    }
    if let Some((t, f)) = &r.fault {
        bail!("the stream ended in a fault at {t:.3} s: {f}");
    }
    Ok(())
}
