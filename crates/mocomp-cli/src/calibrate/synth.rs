//! `mocomp calibrate synth`: a synthetic pairs file with known X and Y.

use anyhow::{Context, Result};
use clap::Args;
use mocomp_calib::synth::{SynthOptions, pairs_file, synthesize};
use mocomp_geom::text::transform;
use std::io::Write;
use std::path::PathBuf;

/// Write a synthetic pairs file with known X and Y, for trying things out.
#[derive(Debug, Clone, Args)]
pub struct SynthCmd {
    /// Where to write it.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Number of pairs.
    #[arg(long, default_value_t = 20)]
    count: usize,
    /// RNG seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// True X = flange_from_marker (default: 12 cm out on the flange, turned).
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = crate::args::six, allow_hyphen_values = true)]
    x: Option<[f64; 6]>,
    /// True Y = base_from_tracker (default: 1.5 m from the robot, facing it).
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = crate::args::six, allow_hyphen_values = true)]
    y: Option<[f64; 6]>,
    /// Tracker noise per axis: millimetres, degrees.
    #[arg(long, value_name = "MM,DEG", default_value = "0.1,0.1", value_parser = crate::args::noise_pair)]
    tracker_noise: [f64; 2],
    /// Robot noise per axis: millimetres, degrees.
    #[arg(long, value_name = "MM,DEG", default_value = "0.03,0.01", value_parser = crate::args::noise_pair)]
    robot_noise: [f64; 2],
    /// Shift the flange by up to this much per axis, metres.
    #[arg(long, default_value_t = 0.20)]
    spread_m: f64,
}

impl SynthCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let mut o = SynthOptions {
            count: self.count,
            seed: self.seed,
            translation_spread_m: self.spread_m,
            noise: Some(super::noise(self.tracker_noise, self.robot_noise)),
            ..Default::default()
        };
        if let Some(x) = &self.x {
            o.flange_from_marker = crate::args::pose("--x", x)?;
        }
        if let Some(y) = &self.y {
            o.base_from_tracker = crate::args::pose("--y", y)?;
        }
        let pairs = synthesize(&o)?;
        let text = pairs_file(&o, &pairs)?;
        std::fs::write(&self.out, text)
            .with_context(|| format!("--out {}: cannot write", self.out.display()))?;
        writeln!(out, "wrote {} pairs to {}", pairs.len(), self.out.display())?;
        let x = transform("true X = flange_from_marker", &o.flange_from_marker, true);
        let y = transform("true Y = base_from_tracker", &o.base_from_tracker, true);
        write!(out, "{x}{y}")?;
        Ok(())
    }
}
