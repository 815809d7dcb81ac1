//! `mocomp track render`: synthetic frames of a marker, with their truth; optionally also as an
//! Azure Kinect recording (the SDK's own recorder, a device's calibration attached).

use crate::args::DepthModeArg;
use anyhow::Result;
use clap::Args;
use mocomp_app::camera::frames::{self, RenderOptionsDir};
use mocomp_app::camera::k4a_recording as k4a;
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
    /// Camera intrinsics (TOML). Default: a typical Kinect v2, or the Azure Kinect's of
    /// `--k4a-calibration`.
    #[arg(long, value_name = "FILE", conflicts_with = "k4a_calibration")]
    intrinsics: Option<PathBuf>,
    /// Also write the frames as an Azure Kinect recording (.mkv, IR and depth, 30 frames a
    /// second, 15 in wfov-unbinned), which the SDK's playback reads as a camera's.
    #[arg(long, value_name = "FILE.mkv", requires = "k4a_calibration")]
    recording: Option<PathBuf>,
    /// An Azure Kinect's calibration (`calibration.json`, as a device stores it and a recording
    /// attaches it): the frames take its depth camera's intrinsics in `--depth-mode`.
    #[arg(long, value_name = "FILE")]
    k4a_calibration: Option<PathBuf>,
    /// The Azure Kinect depth mode.
    #[arg(long, value_enum, default_value = "nfov-unbinned")]
    depth_mode: DepthModeArg,
    /// The Azure Kinect SDK's directory (libk4a, libk4arecord); default: MOCOMP_K4A_SDK_DIR,
    /// else the system's library path.
    #[arg(long, value_name = "DIR")]
    k4a_sdk: Option<PathBuf>,
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
        let mode = self.depth_mode.mode();
        let sdk = match &self.k4a_calibration {
            Some(_) => Some(k4a::load_sdk(self.k4a_sdk.as_deref())?),
            None => None,
        };
        let k = match (&self.intrinsics, &self.k4a_calibration, &sdk) {
            (Some(p), _, _) => frames::read_intrinsics(p)?,
            (None, Some(c), Some(sdk)) => k4a::intrinsics_from_calibration(sdk, c, mode)?,
            _ => Intrinsics::kinect_v2(),
        };
        let mut recording = match (&self.recording, &self.k4a_calibration, &sdk) {
            (Some(path), Some(c), Some(sdk)) => {
                Some(mocomp_app::camera::k4a_writer::RecordingSink::create(
                    sdk,
                    path,
                    mode,
                    mode.max_fps(),
                    c,
                )?)
            }
            _ => None,
        };
        let o = RenderOptionsDir {
            count: self.count,
            seed: self.seed,
            distractors: self.distractors,
            hide: self.hide,
        };
        frames::render_dir(&self.out, &geometry, &k, &o, recording.as_mut())?;
        writeln!(
            out,
            "wrote {} frames ({}×{}) with truth.jsonl and intrinsics.toml to {}",
            self.count,
            k.width,
            k.height,
            self.out.display()
        )?;
        if let (Some(r), Some(path)) = (recording, &self.recording) {
            let n = r.finish()?;
            writeln!(
                out,
                "wrote them as an Azure Kinect recording ({n} captures) to {}",
                path.display()
            )?;
        }
        Ok(())
    }
}
