//! A head surface read, mended and described: what `mocomp head inspect` prints and what
//! `[head] mesh` loads.

use crate::error::HeadError;
use crate::formats::{self, Format, ReadSurface, read_surface, unit_name};
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
    /// How the surface was made, when it was segmented from a volume rather than read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub segmentation: Option<Segmentation>,
}

/// How a scalp was segmented from a volume (filled in by `mocomp-mri`): what a reader of the
/// inspection needs to judge the surface, in the volume's own terms.
#[derive(Debug, Clone, Serialize)]
pub struct Segmentation {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// The voxel's size along i, j, k, mm.
    pub voxel_mm: [f64; 3],
    /// The intensity threshold: voxels at or above it are head.
    pub threshold: f64,
    /// `otsu` or `given`.
    pub threshold_from: &'static str,
    /// The volume's least and greatest intensity.
    pub intensity_range: [f64; 2],
    /// Voxels at or above the threshold.
    pub above_threshold: usize,
    /// Separate 6-connected pieces above it (the largest is the head; the rest are dropped).
    pub pieces: usize,
    /// Voxels of the largest piece.
    pub head_voxels: usize,
    /// Voxels added by closing narrow openings (ear canals), then filling what is enclosed in
    /// 3-D, then in each axial slice (the spinal canal, the CSF, the airways open only at the
    /// volume's edge).
    pub filled_voxels: usize,
    /// The closing's radius, mm.
    pub closing_mm: f64,
    /// The volume's faces the head reaches: the scan ends inside the head there, and the model
    /// is cut flat where it ends (the neck at the bottom is usual; a nose or ears cut off are
    /// not, and the real head stands out beyond the model there).
    pub cut_by_scan: Vec<ScanEdge>,
    /// Triangles of the isosurface on the voxel grid, before it was simplified.
    pub isosurface_triangles: usize,
    /// The most triangles asked for.
    pub max_triangles: usize,
    /// Taubin smoothing passes.
    pub smoothing_passes: usize,
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
    describe(file, read_surface(file, bytes, unit)?, None)
}

/// Mends a surface as read and describes it (and how it was made, when it was segmented).
pub fn describe(
    file: &str,
    s: ReadSurface,
    segmentation: Option<Segmentation>,
) -> Result<(Mesh, Inspection), HeadError> {
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
        segmentation,
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
        if let Some(g) = &self.segmentation {
            writeln!(f, "  {g}")?;
        }
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

/// A face of the volume the head reaches.
#[derive(Debug, Clone, Serialize)]
pub struct ScanEdge {
    /// Which way the face looks in the image's frame: `left`, `right`, `posterior`,
    /// `anterior`, `inferior` or `superior`.
    pub side: &'static str,
    /// Head voxels on it.
    pub voxels: usize,
    /// The centre of the rectangle in the face's plane (half a voxel beyond the last voxels'
    /// centres) that holds the head's voxels on the face, image frame, m.
    pub centre_m: [f64; 3],
    /// The plane's unit normal, out of the scan, image frame.
    pub outward: [f64; 3],
    /// The rectangle's first axis (unit, in the plane; the second is `outward × along`).
    pub along: [f64; 3],
    /// Half its sides along the two axes, m.
    pub half_m: [f64; 2],
}

impl ScanEdge {
    /// The patch as the head model keeps it (image frame).
    pub fn cut(&self) -> crate::ScanCut {
        use mocomp_geom::nalgebra::{Point3, Unit, Vector3};
        crate::ScanCut {
            side: self.side,
            centre: Point3::from(self.centre_m),
            outward: Unit::new_normalize(Vector3::from(self.outward)),
            along: Unit::new_normalize(Vector3::from(self.along)),
            half_m: self.half_m,
        }
    }
}

impl fmt::Display for Segmentation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [i, j, k] = self.dims;
        let [a, b, c] = self.voxel_mm;
        write!(
            f,
            "segmented: {i} × {j} × {k} voxels of {a:.2} × {b:.2} × {c:.2} mm, intensities \
             {:.1}–{:.1}; threshold {:.1} ({}); {} voxels above it in {} piece{}, the head's {} \
             kept, {} added by a {:.1} mm closing and filling; isosurface of {} triangles, {} smoothing passes, \
             decimated to at most {}",
            self.intensity_range[0],
            self.intensity_range[1],
            self.threshold,
            self.threshold_from,
            self.above_threshold,
            self.pieces,
            if self.pieces == 1 { "" } else { "s" },
            self.head_voxels,
            self.filled_voxels,
            self.closing_mm,
            self.isosurface_triangles,
            self.smoothing_passes,
            self.max_triangles
        )?;
        if !self.cut_by_scan.is_empty() {
            let sides: Vec<String> = self
                .cut_by_scan
                .iter()
                .map(|e| format!("{} ({} voxels)", e.side, e.voxels))
                .collect();
            write!(
                f,
                "\n  cut by the scan's edge (the model is flat where the scan ends): {}",
                sides.join(", ")
            )?;
        }
        Ok(())
    }
}
