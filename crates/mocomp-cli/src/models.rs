//! `mocomp models`: the model table.

use anyhow::Result;
use clap::Args;
use mocomp_kin::MODELS;
use serde::Serialize;
use std::io::Write;

#[derive(Serialize)]
struct ModelJson {
    name: &'static str,
    d1: f64,
    a2: f64,
    a3: f64,
    d4: f64,
    d5: f64,
    d6: f64,
    max_speed_rad_s: [f64; 6],
    lower_limits_rad: [Option<f64>; 6],
    upper_limits_rad: [Option<f64>; 6],
    control_period_s: f64,
}

/// The model table: DH parameters, maximum joint speeds, control periods.
#[derive(Debug, Clone, Args)]
pub struct ModelsCmd {
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

impl ModelsCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        print(out, self.json)
    }
}

fn print(out: &mut dyn Write, json: bool) -> Result<()> {
    let finite = |v: &[f64; 6]| v.map(|x| x.is_finite().then_some(x));
    if json {
        let rows: Vec<ModelJson> = MODELS
            .iter()
            .map(|m| ModelJson {
                name: m.name,
                d1: m.geometry.d1,
                a2: m.geometry.a2,
                a3: m.geometry.a3,
                d4: m.geometry.d4,
                d5: m.geometry.d5,
                d6: m.geometry.d6,
                max_speed_rad_s: m.max_speed,
                lower_limits_rad: finite(&m.lower_limits),
                upper_limits_rad: finite(&m.upper_limits),
                control_period_s: m.series.period_s(),
            })
            .collect();
        writeln!(out, "{}", serde_json::to_string(&rows)?)?;
        return Ok(());
    }
    writeln!(
        out,
        "model  {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}  max joint speed (deg/s)    period",
        "d1 (m)", "a2", "a3", "d4", "d5", "d6"
    )?;
    for m in &MODELS {
        let g = &m.geometry;
        let speeds: Vec<String> = m
            .max_speed
            .iter()
            .map(|v| format!("{:.0}", v.to_degrees()))
            .collect();
        writeln!(
            out,
            "{:<6} {:>8.5} {:>8.5} {:>8.5} {:>8.5} {:>8.5} {:>8.5}  {:<26} {:.0} ms",
            m.name,
            g.d1,
            g.a2,
            g.a3,
            g.d4,
            g.d5,
            g.d6,
            speeds.join(","),
            m.series.period_s() * 1000.0
        )?;
    }
    writeln!(
        out,
        "joint limits: ±360° on every joint; UR3/UR3e wrist 3 turns without limit"
    )?;
    Ok(())
}
