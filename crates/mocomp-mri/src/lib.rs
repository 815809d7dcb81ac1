//! The patient's scalp segmented from a T1 MRI in NIfTI, as InVesalius makes it: the intensity
//! threshold (Otsu's, or the operator's), the largest connected piece above it, everything it
//! encloses filled, an isosurface of the result smoothed and made no larger than asked, in the
//! image's own RAS frame (its sform, else its qform), metres.
//!
//! Pure: bytes in, mesh out. The caller reads the file and decides what to do with the result.
//!
//! - [`volume`]: the NIfTI-1 reader, every declared size checked before allocating;
//! - [`threshold`]: Otsu's threshold;
//! - [`mask`]: the head's voxels, its largest piece, the closing and the fills;
//! - [`surface`]: the isosurface and its smoothing;
//! - [`decimate`]: the surface brought to the size asked, a closed manifold still;
//! - [`segment`]: the steps in order, and what the scan cuts off;
//! - [`slice`]: the volume's axial, coronal and sagittal planes through a point, for a screen.

pub mod decimate;
pub mod error;
pub mod mask;
pub mod segment;
pub mod slice;
pub mod surface;
pub mod threshold;
pub mod volume;

pub use error::MriError;
pub use mask::Mask;
pub use segment::{Scalp, segment};
pub use volume::{Volume, read_volume};

use mocomp_geom::LengthUnit;
use mocomp_head::Mesh;
use mocomp_head::formats::{Format, ReadSurface};
use mocomp_head::inspect::{Inspection, describe};

/// How to segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentOptions {
    /// The intensity at and above which a voxel is head; `None`: Otsu's.
    pub threshold: Option<f64>,
    /// The most triangles the surface may have.
    pub max_triangles: usize,
    /// Taubin smoothing passes.
    pub smoothing_passes: usize,
}

/// The most triangles a segmented scalp has unless asked otherwise: what the loop's budget was
/// measured with (a 100 k-triangle scalp builds in under 2 s).
pub const DEFAULT_MAX_TRIANGLES: usize = 100_000;

/// Which scalp this code makes of a volume: part of the key a segmented scalp is kept on disk
/// under (`mocomp-app`'s scalp cache), so a scalp made by other code is never read back as
/// this code's. Raise it with any change to what [`segment`] or the mending after it
/// (`mocomp_head::repair`) make of the same bytes.
pub const SCALP_REVISION: u32 = 1;

/// The fewest triangles a scalp may be asked for.
pub const MIN_TRIANGLES: usize = 1_000;

/// A segmentation option that will not do: which, what it held, why.
#[derive(Debug, Clone, PartialEq)]
pub struct BadOption {
    /// The option's name (`threshold`, `max_triangles`); each caller spells it its own way.
    pub option: &'static str,
    /// What it held.
    pub value: String,
    /// Why that will not do.
    pub why: &'static str,
}

impl SegmentOptions {
    /// `threshold` and `max_triangles`, checked.
    pub fn new(threshold: Option<f64>, max_triangles: usize) -> Result<Self, BadOption> {
        if let Some(t) = threshold
            && !t.is_finite()
        {
            return Err(BadOption {
                option: "threshold",
                value: t.to_string(),
                why: "not a number",
            });
        }
        if max_triangles < MIN_TRIANGLES {
            return Err(BadOption {
                option: "max_triangles",
                value: max_triangles.to_string(),
                why: "a scalp needs 1000 triangles or more",
            });
        }
        Ok(Self {
            threshold,
            max_triangles,
            ..Self::default()
        })
    }
}

impl Default for SegmentOptions {
    fn default() -> Self {
        Self {
            threshold: None,
            max_triangles: DEFAULT_MAX_TRIANGLES,
            smoothing_passes: 10,
        }
    }
}

/// Segments the scalp (see [`segment`]), mends it and describes it as `mocomp head inspect`
/// does a surface file; also returns the scalp (its mask, for writing out).
pub fn inspect_volume(
    file: &str,
    bytes: &[u8],
    unit: Option<LengthUnit>,
    options: &SegmentOptions,
) -> Result<(Mesh, Inspection, Scalp), MriError> {
    let scalp = segment(file, bytes, unit, options)?;
    let extent = scalp.mesh.bounds().map_or(0.0, |b| b.extent());
    mocomp_head::formats::check_size(file, extent, scalp.unit.0)?;
    let read = ReadSurface {
        mesh: scalp.mesh.clone(),
        format: Format::Nifti,
        unit: scalp.unit.0,
        unit_from_format: scalp.unit.1,
        frame: scalp.frame.clone(),
    };
    let (mesh, inspection) = describe(file, read, Some(scalp.segmentation.clone()))?;
    Ok((mesh, inspection, scalp))
}
