//! `mocomp head inspect FILE`: a head surface read and mended, or a T1 MRI's scalp segmented
//! ([`mocomp_app::files::head`]), what it held and what was done, the mesh and a picture of it
//! written out; `mocomp head eeg`: the 10-20 positions on that scalp.

use clap::{Args, Subcommand};
use mocomp_app::navigation::eeg_report;
use mocomp_geom::LengthUnit;
use std::io::Write;
use std::path::PathBuf;

/// The patient's head from a scan.
#[derive(Debug, Clone, Args)]
pub struct HeadCmd {
    #[command(subcommand)]
    command: HeadCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum HeadCommand {
    Inspect(InspectCmd),
    Eeg(EegCmd),
}

/// The 10-20 (or 10-10) positions on the scalp of `[head] mesh`, measured from the nasion, the
/// inion and the preauricular points in `[head.landmarks]`: image coordinates (RAS), mm.
#[derive(Debug, Clone, Args)]
pub struct EegCmd {
    /// The configuration whose `[head]` holds the scan and its landmarks.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// Which positions: 10-20 (21) or 10-10 (61, on and above the circumference).
    #[arg(long, value_name = "10-20|10-10", default_value = "10-20")]
    system: mocomp_nav::System,
    /// Print one JSON object, `{"F3": [x, y, z], …}` in mm.
    #[arg(long)]
    json: bool,
}

impl EegCmd {
    fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let setup = mocomp_app::config::Setup::load(&self.config)?;
        let positions = mocomp_app::navigation::eeg_positions(&setup, self.system)?;
        // Where the landmarks lie against the scalp: said on standard error, so the positions
        // stay the only thing on standard output.
        let offsets = mocomp_app::navigation::landmark_offsets(&setup)?;
        for line in eeg_report::landmark_lines(&offsets) {
            eprintln!("{line}");
        }
        if self.json {
            writeln!(out, "{}", eeg_report::json(&positions))?;
        } else {
            for p in &positions {
                writeln!(out, "{}", eeg_report::line(p))?;
            }
        }
        Ok(())
    }
}

/// Read a head surface (STL, OBJ, PLY, GIfTI, FreeSurfer), or segment the scalp of a T1 MRI
/// (NIfTI .nii/.nii.gz): its vertices, triangles, bounds, whether it is closed, its holes, the
/// frame and unit it was read in, how it was segmented and what was mended.
#[derive(Debug, Clone, Args)]
pub struct InspectCmd {
    /// The surface or volume file.
    file: PathBuf,
    /// The unit of a format that carries none (STL, OBJ, PLY) or of a NIfTI whose header states
    /// none (given, it is taken over the header's): mm or m. GIfTI and FreeSurfer surfaces are
    /// millimetres by their standards.
    #[arg(long, value_name = "mm|m", value_parser = mocomp_head::formats::parse_unit)]
    units: Option<LengthUnit>,
    /// NIfTI: the intensity at and above which a voxel is head (default: Otsu's threshold).
    #[arg(long, value_name = "INTENSITY")]
    threshold: Option<f64>,
    /// NIfTI: the most triangles the segmented scalp may have.
    #[arg(long, value_name = "N", default_value_t = mocomp_mri::DEFAULT_MAX_TRIANGLES)]
    max_triangles: usize,
    /// Write the mended or segmented surface here (binary PLY, millimetres).
    #[arg(long, value_name = "OUT.ply")]
    write_mesh: Option<PathBuf>,
    /// Draw the mended surface from the front, the left and above into this PNG.
    #[arg(long, value_name = "OUT.png")]
    png: Option<PathBuf>,
    /// Print one JSON object (`vertices`, `faces`, `closed`, `holes`, `bounds_m`, `repairs`, …).
    #[arg(long)]
    json: bool,
}

impl HeadCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        let c = match self.command {
            HeadCommand::Inspect(c) => c,
            HeadCommand::Eeg(e) => return e.run(out),
        };
        let segment =
            mocomp_mri::SegmentOptions::new(c.threshold, c.max_triangles).map_err(|e| {
                crate::UsageError(format!(
                    "--{} {}: {}",
                    e.option.replace('_', "-"),
                    e.value,
                    e.why
                ))
            })?;
        let (mesh, report) = mocomp_app::files::head::inspect_file(&c.file, c.units, &segment)?;
        if let Some(p) = &c.write_mesh {
            mocomp_app::files::head::write_mesh(p, &mesh)?;
        }
        if let Some(p) = &c.png {
            mocomp_app::files::head::write_views(p, &mesh, 400)?;
        }
        crate::print::report(out, &report, c.json)?;
        if !c.json {
            for (what, path) in [
                ("mesh", &c.write_mesh),
                ("views (front, left, top)", &c.png),
            ] {
                if let Some(p) = path {
                    writeln!(out, "wrote the {what} to {}", p.display())?;
                }
            }
        }
        Ok(())
    }
}
