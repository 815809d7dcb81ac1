//! `mocomp track`: fiducial tracking in a directory of IR + depth frames
//! ([`mocomp_app::camera::frames`]) or an Azure Kinect recording ([`mocomp_app::camera::k4a_recording`]), one line per
//! frame; `track render` writes such a directory (and recording).

mod render;

use anyhow::Result;
use clap::{Args, Subcommand};
use mocomp_app::camera::{frames, k4a_recording as k4a};
use mocomp_vision::{FrameResult, TrackParams, Tracker};
use std::io::Write;
use std::path::PathBuf;

/// Fiducial tracking in IR + depth frames (directories of 16-bit PNG pairs, or an Azure Kinect
/// recording).
#[derive(Debug, Clone, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct TrackCmd {
    #[command(subcommand)]
    command: Option<TrackCommand>,
    /// Directory of <name>_ir.png / <name>_depth.png pairs (16-bit; depth in mm, 0 = none).
    #[arg(long, value_name = "DIR", required_unless_present = "recording")]
    frames: Option<PathBuf>,
    /// An Azure Kinect recording (.mkv with IR and depth), played through the Azure Kinect SDK;
    /// its own calibration gives the intrinsics.
    #[arg(long, value_name = "FILE.mkv", conflicts_with = "frames")]
    recording: Option<PathBuf>,
    /// The Azure Kinect SDK's directory (libk4a, libk4arecord); default: MOCOMP_K4A_SDK_DIR,
    /// else the system's library path.
    #[arg(long, value_name = "DIR")]
    k4a_sdk: Option<PathBuf>,
    /// Camera intrinsics (TOML: width, height, fx, fy, cx, cy, k1…k6, p1, p2, pixel_centre);
    /// with a recording, instead of its calibration.
    #[arg(long, value_name = "FILE", required_unless_present = "recording")]
    intrinsics: Option<PathBuf>,
    /// Marker geometry: .toml (points_mm), Atracsys .ini or NDI .rom.
    #[arg(long, value_name = "FILE", required = true)]
    geometry: Option<PathBuf>,
    /// Pipeline parameters (TOML; see the book's commands page, book/src/reference/commands.md). Default: built-in values.
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// Write an overlay image per frame into this directory.
    #[arg(long, value_name = "DIR")]
    overlay: Option<PathBuf>,
    /// One JSON line per frame.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Clone, Subcommand)]
enum TrackCommand {
    Render(render::RenderCmd),
}

impl TrackCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        if let Some(TrackCommand::Render(r)) = self.command {
            return r.run(out);
        }
        let Some(geometry_path) = &self.geometry else {
            return Err(crate::UsageError("track needs --geometry".into()).into());
        };
        let geometry = frames::read_geometry(geometry_path)?;
        let params = match &self.params {
            Some(p) => frames::read_params(p)?,
            None => TrackParams::default(),
        };
        let report = geometry.analyze(mocomp_geom::units::mm_to_m(params.match_tolerance_mm));
        for w in &report.warnings {
            eprintln!("warning: {}: {w}", geometry_path.display());
        }
        let given = self
            .intrinsics
            .as_deref()
            .map(frames::read_intrinsics)
            .transpose()?;
        let mut found = 0usize;
        let json = self.json;
        let (count, tail) = if let Some(path) = &self.recording {
            let sdk = k4a::load_sdk(self.k4a_sdk.as_deref())?;
            let mut playback = k4a::open_recording(&sdk, path)?;
            let intrinsics = match given {
                Some(k) => k,
                None => playback
                    .intrinsics()
                    .map_err(|e| mocomp_app::AppError::failed("--recording", e))?,
            };
            let mut tracker = Tracker::new(intrinsics, params, geometry)?;
            let n = k4a::track_recording(
                &mut playback,
                &mut tracker,
                self.overlay.as_deref(),
                &mut |t| {
                    found += usize::from(t.result.detection.is_some());
                    print(&mut *out, t.name, Some(t.device_usec), t.result, json)
                },
            )?;
            let tail = format!(
                " ({} dropped by their timestamps, {} without IR or depth)",
                n.dropped, n.incomplete
            );
            (n.tracked, tail)
        } else {
            let (Some(dir), Some(intrinsics)) = (&self.frames, given) else {
                return Err(crate::UsageError(
                    "track needs --frames and --intrinsics, or --recording".into(),
                )
                .into());
            };
            let mut tracker = Tracker::new(intrinsics, params, geometry)?;
            let n = frames::track_dir(
                dir,
                &mut tracker,
                self.overlay.as_deref(),
                &mut |name, result| {
                    found += usize::from(result.detection.is_some());
                    print(&mut *out, name, None, result, json)
                },
            )?;
            (n, String::new())
        };
        if !json {
            writeln!(out, "found the marker in {found} of {count} frames{tail}")?;
        }
        Ok(())
    }
}

fn print(
    out: &mut dyn Write,
    name: &str,
    device_usec: Option<u64>,
    result: &FrameResult,
    json: bool,
) -> Result<(), mocomp_app::AppError> {
    writeln!(
        out,
        "{}",
        frames::frame_line(name, device_usec, result, json)
    )
    .map_err(|e| mocomp_app::AppError::failed("writing the output", e))
}
