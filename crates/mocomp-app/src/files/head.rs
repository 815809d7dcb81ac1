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
use std::path::Path;

/// The largest head file read, bytes: a 5 M-triangle binary STL is 250 MB; ASCII twice that.
pub const MAX_FILE_BYTES: u64 = 600 << 20;

/// The bytes of `path`, refusing a file over [`MAX_FILE_BYTES`] before reading it.
fn read_capped(path: &Path) -> Result<Vec<u8>, AppError> {
    crate::files::capped::read_capped(path, MAX_FILE_BYTES, "a head file")
}

/// `nii` or `nii.gz` for a NIfTI's path, by its name (the one place that says what a NIfTI is
/// called).
pub fn nifti_extension(p: &Path) -> Option<&'static str> {
    let name = p.file_name()?.to_str()?.to_ascii_lowercase();
    if name.ends_with(".nii.gz") {
        Some("nii.gz")
    } else if name.ends_with(".nii") {
        Some("nii")
    } else {
        None
    }
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
    let bytes = read_capped(path)?;
    inspect_bytes(&path.display().to_string(), &bytes, unit, segment)
}

/// [`inspect_file`] on the file's bytes.
fn inspect_bytes(
    name: &str,
    bytes: &[u8],
    unit: Option<LengthUnit>,
    segment: &SegmentOptions,
) -> Result<(Mesh, Inspection), AppError> {
    if is_volume(name, bytes) {
        let (mesh, inspection, _) = mocomp_mri::inspect_volume(name, bytes, unit, segment)
            .map_err(|e| AppError::failed("segmenting the scalp", e))?;
        return Ok((mesh, inspection));
    }
    mocomp_head::inspect::inspect(name, bytes, unit)
        .map_err(|e| AppError::failed("reading the head", e))
}

fn is_volume(name: &str, bytes: &[u8]) -> bool {
    formats::Format::detect(name, bytes).ok() == Some(formats::Format::Nifti)
}

/// Where a head model's scalp came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScalpFrom {
    /// A surface file, read and mended.
    Surface,
    /// A T1, segmented now (and kept for the next command, where a cache is).
    Segmented,
    /// A T1's scalp segmented before and kept ([`crate::files::scalp_cache`]).
    Kept,
}

/// The scalp of the file at `path`, mended, in the file's frame, and where a scan ends inside
/// the head (a T1's scalp from the cache when it was segmented before with the same options).
fn scalp(
    path: &Path,
    unit: Option<LengthUnit>,
    segment: &SegmentOptions,
    cache: Option<&Path>,
) -> Result<(crate::files::scalp_cache::Scalp, ScalpFrom), AppError> {
    let name = path.display().to_string();
    let bytes = read_capped(path)?;
    if !is_volume(&name, &bytes) {
        let (mesh, _) = inspect_bytes(&name, &bytes, unit, segment)?;
        let cuts = Vec::new();
        return Ok((
            crate::files::scalp_cache::Scalp { mesh, cuts },
            ScalpFrom::Surface,
        ));
    }
    let key = crate::files::scalp_cache::key(&bytes, unit, segment);
    if let Some(kept) = cache.and_then(|f| crate::files::scalp_cache::load(f, &key)) {
        return Ok((kept, ScalpFrom::Kept));
    }
    let (mesh, inspection) = inspect_bytes(&name, &bytes, unit, segment)?;
    let cuts = inspection
        .segmentation
        .iter()
        .flat_map(|s| &s.cut_by_scan)
        .map(|edge| edge.cut())
        .collect();
    let scalp = crate::files::scalp_cache::Scalp { mesh, cuts };
    if let Some(f) = cache {
        // A cache that cannot be written costs the next command the segmentation, no more.
        crate::files::scalp_cache::store(f, &key, &scalp).ok();
    }
    Ok((scalp, ScalpFrom::Segmented))
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
/// marker's frame, with the distance field the loop asks built; and where its scalp came from.
/// A T1's scalp segmented before with the same options, and a field built before for the same
/// mesh, are read back rather than made again, from where the environment keeps them
/// ([`crate::files::cache::root`]).
pub fn load_head(
    path: &Path,
    unit: Option<LengthUnit>,
    segment: &SegmentOptions,
    head_from_image: &Isometry3<f64>,
) -> Result<(HeadModel, ScalpFrom), AppError> {
    let cache = crate::files::cache::root();
    load_head_keeping_in(path, unit, segment, head_from_image, cache.as_deref())
}

/// [`load_head`], keeping segmented scalps and built fields under `cache` (none: making them
/// every time).
pub fn load_head_keeping_in(
    path: &Path,
    unit: Option<LengthUnit>,
    segment: &SegmentOptions,
    head_from_image: &Isometry3<f64>,
    cache: Option<&Path>,
) -> Result<(HeadModel, ScalpFrom), AppError> {
    let (scalp, from) = scalp(path, unit, segment, cache)?;
    let name = path.display().to_string();
    // Where a segmented scan ends inside the head, carried along with the scalp.
    let cuts = scalp
        .cuts
        .iter()
        .map(|cut| cut.transformed(head_from_image))
        .collect();
    let head = build(scalp.mesh.transformed(head_from_image), &name, cache)
        .map_err(|e| AppError::failed("building the head", e))?
        .with_cuts(cuts);
    Ok((HeadModel::new(Head::Mesh(std::sync::Arc::new(head))), from))
}

/// The head of `mesh`, its field's grid read back from under `cache` when it was built before for
/// this very mesh, else built (and kept: a cache that cannot be written costs the next command
/// the build, no more).
fn build(mesh: Mesh, name: &str, cache: Option<&Path>) -> Result<MeshHead, mocomp_head::HeadError> {
    let Some(root) = cache else {
        return MeshHead::new(mesh, name);
    };
    let key = crate::files::field_cache::key(&mesh);
    let (head, taken) = match crate::files::field_cache::load(root, &key) {
        Some(grid) => MeshHead::with_field_grid(mesh, name, grid)?,
        None => (MeshHead::new(mesh, name)?, false),
    };
    if !taken {
        crate::files::field_cache::store(root, &key, &head.field_grid()).ok();
    }
    Ok(head)
}
