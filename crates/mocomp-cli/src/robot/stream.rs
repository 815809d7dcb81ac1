//! `mocomp robot stream`: the servo streaming check ([`mocomp_app::robot::servo_check`]), printed.

use anyhow::{Result, bail};
use clap::Args;
use mocomp_app::robot::servo_check::{StreamOptions, stream};
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
        let sim = self
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
        crate::print::report(out, &r, self.json)?;
        if let Some((t, f)) = &r.fault {
            // The simulated controller's own words for it, where it is this process's.
            let why = sim
                .as_ref()
                .and_then(|s| {
                    s.with(|c| c.events().0)
                        .into_iter()
                        .rev()
                        .find(|e| e.text.contains("stop"))
                })
                .map(|e| format!("; the simulator at {:.3} s: {}", e.time_s, e.text))
                .unwrap_or_default();
            // Whose silence it was: a gap here past the watchdog is this client's (its host),
            // none is the controller's side.
            bail!(
                "the stream ended in a fault at {t:.3} s: {f} (longest gap between this \
                 client's commands: {:.1} ms){why}",
                r.period_max_ms
            );
        }
        Ok(())
    }
}
