//! `mocomp ursim`: a simulated UR controller on a loopback address, printing its events.

use anyhow::Result;
use clap::Args;
use mocomp_app::world::SimulatorOptions;
use mocomp_kin::Model;
use mocomp_ursim::Sim;
use std::io::Write;
use std::net::IpAddr;

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
    /// The arm's joints at power-on, rad (a real arm starts wherever it was left; default: the
    /// working pose 0,-1.3,1.6,-1.87,-1.57,0).
    #[arg(long, value_name = "Q1,...,Q6", value_parser = crate::args::six, allow_hyphen_values = true)]
    initial_joints: Option<[f64; 6]>,
    /// Real-time scheduling of the controller's threads: `fifo:N` (SCHED_FIFO priority N, 1–99;
    /// the default fifo:49 keeps below `mocomp run`'s loop at 50, as a controller on its own
    /// computer never competes with it) or `off` (normal scheduling, as a busy controller).
    #[arg(long, value_name = "fifo:N|off", default_value = "fifo:49", value_parser = realtime)]
    realtime: Realtime,
    /// Pin the controller's threads to this CPU (on a shared machine, away from the loop's).
    #[arg(long, value_name = "N")]
    cpu: Option<usize>,
    /// Take the cell's own events from standard input, one per line: `protective stop [why]`,
    /// `emergency stop`, `emergency stop release` (what a person in the room causes, which no
    /// network command of a real controller does).
    #[arg(long)]
    cell_stdin: bool,
}

/// `--realtime`: a SCHED_FIFO priority, or none.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Realtime(Option<u8>);

/// Parses `--realtime`: `fifo:N` (1–99) or `off`.
fn realtime(s: &str) -> Result<Realtime, String> {
    if s == "off" {
        return Ok(Realtime(None));
    }
    let n = s
        .strip_prefix("fifo:")
        .ok_or_else(|| format!("{s:?}: expected fifo:N (N 1–99) or off"))?;
    match n.parse::<u8>() {
        Ok(p) if (1..=99).contains(&p) => Ok(Realtime(Some(p))),
        _ => Err(format!("{s:?}: the priority must be 1–99")),
    }
}

impl UrsimCmd {
    /// Serves until killed (or for `seconds`), printing the controller's events.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        if let Some(s) = self.seconds {
            crate::args::positive("--seconds", s)?;
        }
        let options = SimulatorOptions {
            initial_q: self.initial_joints,
            priority: self.realtime.0,
            cpu: self.cpu,
        };
        let sim = start(self.model, self.host, &options).map_err(|e| {
            if let Some(mocomp_app::AppError::Config(m)) = e.downcast_ref() {
                crate::UsageError(format!("--initial-joints: {m}")).into()
            } else {
                e
            }
        })?;
        if self.cell_stdin {
            let sim = sim.handle();
            std::thread::Builder::new()
                .name("ursim-cell".into())
                .spawn(move || {
                    mocomp_ursim::cell::follow(std::io::stdin().lock(), &sim, |why| {
                        eprintln!("error: {why}");
                    });
                })?;
        }
        mocomp_app::world::serve_simulator(out, &sim, self.model, self.seconds)?;
        Ok(())
    }
}

/// Starts a simulator, printing the warning when it got no real-time priority.
pub fn start(model: Model, host: IpAddr, options: &SimulatorOptions) -> Result<Sim> {
    let (sim, warning) = mocomp_app::world::start_simulator(model, host, options)?;
    if let Some(w) = warning {
        eprintln!("warning: {w}");
    }
    Ok(sim)
}
