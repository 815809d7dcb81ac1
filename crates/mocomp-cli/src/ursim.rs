//! `mocomp ursim`: a simulated UR controller on a loopback address, printing its events.

use anyhow::Result;
use clap::Args;
use mocomp_kin::Model;
use mocomp_ursim::Sim;
use std::io::Write;
use std::net::IpAddr;
use std::time::{Duration, Instant};

/// A simulated UR controller on a loopback address, for mocomp or any UR client.
///
/// It serves the standard ports (RTDE 30004, dashboard
/// 29999, script 30001–30003), for mocomp or any UR client (ur_rtde, …).
#[derive(Debug, Clone, Args)]
pub struct UrsimCmd {
    /// Robot model (ur3, ur5, ur10: CB3 at 125 Hz; ur3e … ur30: e-Series at 500 Hz).
    #[arg(long, value_parser = crate::args::model, default_value = "ur3")]
    model: Model,
    /// Address to serve on; one loopback address per simulated robot.
    #[arg(long, default_value = "127.0.0.2")]
    host: IpAddr,
    /// Stop after this many seconds (default: run until killed).
    #[arg(long)]
    seconds: Option<f64>,
}

impl UrsimCmd {
    /// Serves until killed (or for `seconds`), printing the controller's events.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        if let Some(s) = self.seconds {
            crate::args::positive("--seconds", s)?;
        }
        let sim = start(self.model, self.host)?;
        serve(out, &sim, self.model, self.seconds)
    }
}

/// Starts a simulator, printing the warning when it got no real-time priority.
pub fn start(model: Model, host: IpAddr) -> Result<Sim> {
    let (sim, warning) = mocomp_app::world::start_simulator(model, host)?;
    if let Some(w) = warning {
        eprintln!("warning: {w}");
    }
    Ok(sim)
}

fn serve(out: &mut dyn Write, sim: &Sim, model: Model, seconds: Option<f64>) -> Result<()> {
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
