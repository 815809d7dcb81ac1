//! `mocomp track`: fiducial tracking in a directory of IR + depth frames
//! ([`mocomp_app::frames`]), one line per frame; `track render` writes such a directory.

mod render;

use anyhow::Result;
use clap::{Args, Subcommand};
use mocomp_app::frames;
use mocomp_geom::units::m_to_mm;
use mocomp_vision::{FrameResult, TrackParams, Tracker};
use serde::Serialize;
use std::io::Write;
use std::path::PathBuf;

#[derive(Serialize)]
struct FrameJson<'a> {
    frame: &'a str,
    found: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    tracker_from_marker: Option<[[f64; 4]; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fre_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    blobs: usize,
}

/// Fiducial tracking in IR + depth frames (directories of 16-bit PNG pairs).
#[derive(Debug, Clone, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct TrackCmd {
    #[command(subcommand)]
    command: Option<TrackCommand>,
    /// Directory of <name>_ir.png / <name>_depth.png pairs (16-bit; depth in mm, 0 = none).
    #[arg(long, value_name = "DIR", required = true)]
    frames: Option<PathBuf>,
    /// Camera intrinsics (TOML: width, height, fx, fy, cx, cy, k1, k2, k3, p1, p2, pixel_centre).
    #[arg(long, value_name = "FILE", required = true)]
    intrinsics: Option<PathBuf>,
    /// Marker geometry: .toml (points_mm), Atracsys .ini or NDI .rom.
    #[arg(long, value_name = "FILE", required = true)]
    geometry: Option<PathBuf>,
    /// Pipeline parameters (TOML; see README.md). Default: built-in values.
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
        let (Some(dir), Some(intrinsics), Some(geometry)) =
            (&self.frames, &self.intrinsics, &self.geometry)
        else {
            return Err(crate::UsageError(
                "track needs --frames, --intrinsics and --geometry".into(),
            )
            .into());
        };
        let intrinsics = frames::read_intrinsics(intrinsics)?;
        let geometry_path = geometry;
        let geometry = frames::read_geometry(geometry_path)?;
        let params = match &self.params {
            Some(p) => frames::read_params(p)?,
            None => TrackParams::default(),
        };
        let report = geometry.analyze(mocomp_geom::units::mm_to_m(params.match_tolerance_mm));
        for w in &report.warnings {
            eprintln!("warning: {}: {w}", geometry_path.display());
        }
        let mut tracker = Tracker::new(intrinsics, params, geometry)?;
        let mut found = 0usize;
        let json = self.json;
        let count = frames::track_dir(
            dir,
            &mut tracker,
            self.overlay.as_deref(),
            &mut |name, result| {
                found += usize::from(result.detection.is_some());
                print(&mut *out, name, result, json)
                    .map_err(|e| mocomp_app::AppError::failed("writing the output", e))
            },
        )?;
        if !json {
            writeln!(out, "found the marker in {found} of {count} frames")?;
        }
        Ok(())
    }
}

fn print(out: &mut dyn Write, name: &str, result: &FrameResult, json: bool) -> std::io::Result<()> {
    if json {
        let j = FrameJson {
            frame: name,
            found: result.detection.is_some(),
            tracker_from_marker: result
                .detection
                .as_ref()
                .map(|d| frames::rows_mm(&d.tracker_from_marker)),
            fre_mm: result.detection.as_ref().map(|d| m_to_mm(d.fre_m)),
            reason: result.not_found.as_ref().map(|r| r.to_string()),
            blobs: result.blobs.len(),
        };
        let line = serde_json::to_string(&j).map_err(std::io::Error::other)?;
        return writeln!(out, "{line}");
    }
    match (&result.detection, &result.not_found) {
        (Some(d), _) => {
            let t = d.tracker_from_marker.translation.vector;
            writeln!(
                out,
                "{name}: found at ({:.1}, {:.1}, {:.1}) mm, FRE {:.2} mm, {} blobs",
                m_to_mm(t.x),
                m_to_mm(t.y),
                m_to_mm(t.z),
                m_to_mm(d.fre_m),
                result.blobs.len()
            )
        }
        (None, Some(r)) => writeln!(out, "{name}: not found: {r} ({} blobs)", result.blobs.len()),
        (None, None) => writeln!(out, "{name}: not found"),
    }
}
