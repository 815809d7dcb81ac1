//! A head surface read, mended and described: what `mocomp head inspect` prints and what
//! `[head] mesh` loads.

use crate::error::HeadError;
use crate::formats::{self, Format, read_surface, unit_name};
use crate::mesh::Mesh;
use crate::repair::{Repairs, repair};
use mocomp_geom::LengthUnit;
use serde::Serialize;
use std::fmt;

/// What a head surface file held and what was made of it.
#[derive(Debug, Clone, Serialize)]
pub struct Inspection {
    /// The file, as named.
    pub file: String,
    /// Its format.
    pub format: Format,
    /// The unit its numbers were read in (`mm` or `m`).
    pub unit: &'static str,
    /// Whether the format fixed that unit (`false`: it was given).
    pub unit_from_format: bool,
    /// The frame the file states for its coordinates.
    pub frame: String,
    /// Vertices and triangles in the file, as it lists them.
    pub read: Counts,
    /// Vertices of the mended surface (duplicates merged, hole fans added).
    pub vertices: usize,
    /// Triangles of the mended surface.
    pub faces: usize,
    /// Whether the surface was closed as read.
    pub closed: bool,
    /// Holes found (and closed).
    pub holes: usize,
    /// The mended surface's box, metres: `[[min x, y, z], [max x, y, z]]`.
    pub bounds_m: [[f64; 3]; 2],
    /// What was mended.
    pub repairs: Repairs,
}

/// Counts as a file lists them.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Counts {
    /// Vertices.
    pub vertices: usize,
    /// Triangles.
    pub faces: usize,
}

/// Reads the surface in `bytes` (the file `file`; `unit` when its format has none), mends it and
/// describes it. The mesh is in metres, in the file's frame.
pub fn inspect(
    file: &str,
    bytes: &[u8],
    unit: Option<LengthUnit>,
) -> Result<(Mesh, Inspection), HeadError> {
    let s = read_surface(file, bytes, unit)?;
    let read = Counts {
        vertices: s.mesh.vertices.len(),
        faces: s.mesh.triangles.len(),
    };
    let (mesh, repairs) = repair(s.mesh, file)?;
    let b = mesh.bounds().ok_or_else(|| HeadError::Empty {
        file: file.into(),
        what: "no vertices".into(),
    })?;
    // The mended surface may have lost pieces: it must still be a head.
    formats::check_size(file, b.extent(), LengthUnit::Metre).map_err(|_| HeadError::Shape {
        file: file.into(),
        what: format!(
            "its outer shell is {:.3} m across, not a head (the rest was {} separate pieces)",
            b.extent(),
            repairs.pieces_dropped
        ),
    })?;
    let inspection = Inspection {
        file: file.into(),
        format: s.format,
        unit: unit_name(s.unit),
        unit_from_format: s.unit_from_format,
        frame: s.frame,
        read,
        vertices: mesh.vertices.len(),
        faces: mesh.triangles.len(),
        closed: repairs.closed_as_read,
        holes: repairs.holes_closed,
        bounds_m: [[b.min.x, b.min.y, b.min.z], [b.max.x, b.max.y, b.max.z]],
        repairs,
    };
    Ok((mesh, inspection))
}

impl fmt::Display for Inspection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [lo, hi] = self.bounds_m;
        let mm = |v: [f64; 3]| format!("({:.1}, {:.1}, {:.1})", v[0] * 1e3, v[1] * 1e3, v[2] * 1e3);
        writeln!(
            f,
            "{}: {}, {} vertices and {} triangles as listed",
            self.file,
            self.format.name(),
            self.read.vertices,
            self.read.faces
        )?;
        writeln!(
            f,
            "  unit: {} ({}); frame: {}",
            self.unit,
            if self.unit_from_format {
                "the format's"
            } else {
                "as given"
            },
            self.frame
        )?;
        writeln!(
            f,
            "  surface: {} vertices, {} triangles, {}; {} hole{}",
            self.vertices,
            self.faces,
            if self.closed {
                "closed as read"
            } else {
                "open as read"
            },
            self.holes,
            if self.holes == 1 { "" } else { "s" }
        )?;
        writeln!(
            f,
            "  bounds: {} to {} mm ({:.1} × {:.1} × {:.1} mm)",
            mm(lo),
            mm(hi),
            (hi[0] - lo[0]) * 1e3,
            (hi[1] - lo[1]) * 1e3,
            (hi[2] - lo[2]) * 1e3
        )?;
        let changes = self.repairs.phrases();
        if changes.is_empty() {
            writeln!(f, "  mended: nothing needed")
        } else {
            writeln!(f, "  mended: {}", changes.join("; "))
        }
    }
}
