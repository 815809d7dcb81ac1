//! `mocomp track render`: synthetic frames of a marker, with their truth.

use anyhow::Result;
use clap::Args;
use mocomp_app::frames::{self, RenderOptionsDir};
use mocomp_vision::Intrinsics;
use std::io::Write;
use std::path::PathBuf;

/// Write synthetic frames of a marker (with ground truth) to a directory.
#[derive(Debug, Clone, Args)]
pub struct RenderCmd {
    /// Output directory.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Marker geometry (.toml, .ini, .rom).
    #[arg(long, value_name = "FILE")]
    geometry: PathBuf,
    /// Camera intrinsics (TOML). Default: a typical Kinect v2.
    #[arg(long, value_name = "FILE")]
    intrinsics: Option<PathBuf>,
    /// Number of frames.
    #[arg(long, default_value_t = 10)]
    count: usize,
    /// RNG seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Add sun spots, reflections and (every fifth frame) a hand.
    #[arg(long)]
    distractors: bool,
    /// Hide this fiducial (1-based) in every frame.
    #[arg(long, value_name = "K")]
    hide: Option<usize>,
}

impl RenderCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let geometry = frames::read_geometry(&self.geometry)?;
        let k = match &self.intrinsics {
            Some(p) => frames::read_intrinsics(p)?,
            None => Intrinsics::kinect_v2(),
        };
        let o = RenderOptionsDir {
            count: self.count,
            seed: self.seed,
            distractors: self.distractors,
            hide: self.hide,
        };
        frames::render_dir(&self.out, &geometry, &k, &o)?;
        writeln!(
            out,
            "wrote {} frames ({}×{}) with truth.jsonl and intrinsics.toml to {}",
            self.count,
            k.width,
            k.height,
            self.out.display()
        )?;
        Ok(())
    }
}
