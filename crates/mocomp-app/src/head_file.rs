//! A head file from disk (`mocomp head inspect`, `[head] mesh`): read with a size limit, a
//! surface decoded and mended by [`mocomp_head`] or a T1 volume's scalp segmented by
//! [`mocomp_mri`], and what was made of it written back out.

use crate::{AppError, Context};
use mocomp_control::HeadModel;
use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_head::inspect::Inspection;
use mocomp_head::render::{Picture, three_views};
use mocomp_head::{Head, Mesh, MeshHead, formats};
use mocomp_mri::SegmentOptions;
use std::io::Read;
use std::path::Path;

/// The largest head file read, bytes: a 5 M-triangle binary STL is 250 MB; ASCII twice that.
pub const MAX_FILE_BYTES: u64 = 600 << 20;

/// The bytes of `path`, refusing a file over [`MAX_FILE_BYTES`] before reading it.
fn read_capped(path: &Path) -> Result<Vec<u8>, AppError> {
    let name = path.display().to_string();
    let file = std::fs::File::open(path).what(|| format!("{name}: cannot open"))?;
    let size = file
        .metadata()
        .what(|| format!("{name}: cannot read its size"))?
        .len();
    if size > MAX_FILE_BYTES {
        return Err(AppError::Config(format!(
            "{name}: {size} bytes, more than the {MAX_FILE_BYTES} a head file may have"
        )));
    }
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .what(|| format!("{name}: cannot read"))?;
    Ok(bytes)
}

/// The T1 volume at `path` (NIfTI, its lengths in `unit` when its header states none), to
/// show: the voxels and their RAS frame.
pub fn read_image(path: &Path, unit: Option<LengthUnit>) -> Result<mocomp_mri::Volume, AppError> {
    let bytes = read_capped(path)?;
    mocomp_mri::read_volume(&path.display().to_string(), &bytes, unit)
        .map_err(|e| AppError::failed(format!("reading the image {}", path.display()), e))
}

/// Reads `path` (refusing a file over [`MAX_FILE_BYTES`] before reading it), decodes it in
/// `unit` when its format has none, and mends it; a NIfTI volume's scalp is segmented as
/// `segment` says.
pub fn inspect_file(
    path: &Path,
    unit: Option<LengthUnit>,
    segment: &SegmentOptions,
) -> Result<(Mesh, Inspection), AppError> {
    let name = path.display().to_string();
    let bytes = read_capped(path)?;
    if formats::Format::detect(&name, &bytes).ok() == Some(formats::Format::Nifti) {
        let (mesh, inspection, _) = mocomp_mri::inspect_volume(&name, &bytes, unit, segment)
            .map_err(|e| AppError::failed("segmenting the scalp", e))?;
        return Ok((mesh, inspection));
    }
    mocomp_head::inspect::inspect(&name, &bytes, unit)
        .map_err(|e| AppError::failed("reading the head", e))
}

/// Writes `mesh` (metres) to `path` as binary PLY in millimetres.
pub fn write_mesh(path: &Path, mesh: &Mesh) -> Result<(), AppError> {
    let bytes = formats::write_ply(mesh, 1e3).map_err(|e| AppError::failed("PLY", e))?;
    std::fs::write(path, bytes).what(|| format!("{}: cannot write", path.display()))
}

/// Draws `mesh` from three sides (`size` pixels each) into the PNG `path`.
pub fn write_views(path: &Path, mesh: &Mesh, size: u32) -> Result<(), AppError> {
    let Picture { width, height, rgb } = three_views(mesh, size);
    let png = mocomp_vision::codec::encode_rgb_png(width, height, &rgb, "the head's views")
        .map_err(|e| AppError::failed("drawing the head", e))?;
    std::fs::write(path, png).what(|| format!("{}: cannot write", path.display()))
}

/// The head model of the surface at `path` (see [`inspect_file`]), its points (and the faces
/// where a segmented scan ends inside the head) carried by `head_from_image` into the head
/// marker's frame, with the distance field the loop asks built.
pub fn load_head(
    path: &Path,
    unit: Option<LengthUnit>,
    segment: &SegmentOptions,
    head_from_image: &Isometry3<f64>,
) -> Result<HeadModel, AppError> {
    let (mesh, inspection) = inspect_file(path, unit, segment)?;
    let name = path.display().to_string();
    // Where a segmented scan ends inside the head, carried along with the scalp.
    let cuts = inspection
        .segmentation
        .iter()
        .flat_map(|s| &s.cut_by_scan)
        .map(|edge| edge.cut().transformed(head_from_image))
        .collect();
    let head = MeshHead::new(mesh.transformed(head_from_image), &name)
        .map_err(|e| AppError::failed("building the head", e))?
        .with_cuts(cuts);
    Ok(HeadModel::new(Head::Mesh(std::sync::Arc::new(head))))
}
