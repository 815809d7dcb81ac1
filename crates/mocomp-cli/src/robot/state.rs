//! `mocomp robot state`: mocomp's client against a UR controller, and what it reports.

use anyhow::{Result, bail};
use clap::Args;
use mocomp_kin::Model;
use mocomp_ur::Robot;
use serde::Serialize;
use std::io::Write;
use std::net::IpAddr;

#[derive(Serialize)]
struct StateJson {
    controller_s: f64,
    actual_q: [f64; 6],
    tcp_pose: [f64; 6],
    robot_mode: String,
    safety_mode: String,
    runtime_state: String,
    fault: Option<String>,
    /// `actual_TCP_force`: N and N·m, base frame.
    tcp_force: [f64; 6],
}

/// Connect, start the control program and print the state.
#[derive(Debug, Clone, Args)]
pub struct StateCmd {
    /// Controller address.
    #[arg(long)]
    host: IpAddr,
    /// Start a simulated controller of this model at --host first.
    #[arg(long, value_parser = crate::args::model)]
    ursim: Option<Model>,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

impl StateCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let _sim = self
            .ursim
            .map(|m| crate::ursim::start(m, self.host, &Default::default()))
            .transpose()?;
        print(out, self.host, self.json)
    }
}

fn print(out: &mut dyn Write, host: IpAddr, json: bool) -> Result<()> {
    let robot = mocomp_app::servo_check::connect(host)?;
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
        tcp_force: s.tcp_force,
    };
    if json {
        writeln!(out, "{}", serde_json::to_string(&j)?)?;
    } else {
        writeln!(
            out,
            "controller {} at {host}: {} / {} / {}; q = {:?} rad; TCP = {:?}; TCP force = {:?} N, N·m (base frame); fault: {}",
            robot.controller_version(),
            j.robot_mode,
            j.safety_mode,
            j.runtime_state,
            j.actual_q,
            j.tcp_pose,
            j.tcp_force,
            j.fault.as_deref().unwrap_or("none")
        )?;
    }
    Ok(())
}
