//! `mocomp head inspect FILE`: a head surface read and mended ([`mocomp_app::head_file`]), what
//! it held and what was done, the mended mesh and a picture of it written out.

use clap::{Args, Subcommand};
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
}

/// Read a head surface (STL, OBJ, PLY, GIfTI, FreeSurfer): its vertices, triangles, bounds,
/// whether it is closed, its holes, the frame and unit it was read in, and what was mended.
#[derive(Debug, Clone, Args)]
pub struct InspectCmd {
    /// The surface file.
    file: PathBuf,
    /// The unit of a format that carries none (STL, OBJ, PLY): mm or m. GIfTI and FreeSurfer
    /// surfaces are millimetres by their standards.
    #[arg(long, value_name = "mm|m", value_parser = mocomp_head::formats::parse_unit)]
    units: Option<LengthUnit>,
    /// Write the mended surface here (binary PLY, millimetres).
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
        let HeadCommand::Inspect(c) = self.command;
        let (mesh, report) = mocomp_app::head_file::inspect_file(&c.file, c.units)?;
        if let Some(p) = &c.write_mesh {
            mocomp_app::head_file::write_mesh(p, &mesh)?;
        }
        if let Some(p) = &c.png {
            mocomp_app::head_file::write_views(p, &mesh, 400)?;
        }
        crate::print::report(out, &report, c.json)?;
        if !c.json {
            for (what, path) in [
                ("mended mesh", &c.write_mesh),
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
