//! The surface formats clinics have the head in, decoded from bytes (the caller reads the file):
//! STL (binary and ASCII), OBJ, PLY (ASCII and binary), GIfTI (`.gii`) and FreeSurfer's binary
//! triangle surfaces (`lh.seghead`, `bem/outer_skin.surf`).
//!
//! Every count a file declares is checked against [`MAX_TRIANGLES`] and [`MAX_VERTICES`], and
//! against the bytes there are, before anything is allocated for it. Units: GIfTI and FreeSurfer
//! surfaces are millimetres by their specifications; STL, OBJ and PLY carry none, so the caller
//! must say (an error says which unit the size suggests, never a silent guess).

mod freesurfer;
mod gifti;
mod obj;
mod ply;
mod stl;

use crate::casing::Casing;
use crate::error::HeadError;
use crate::mesh::Mesh;
use mocomp_geom::LengthUnit;
use serde::Serialize;

pub use ply::write_ply;

/// The most triangles a head model may have (a scalp needs under a million; 5 M is a 1 mm
/// marching-cubes surface of a whole MRI volume).
pub const MAX_TRIANGLES: u64 = 5_000_000;
/// The most vertices.
pub const MAX_VERTICES: u64 = 5_000_000;

/// The smallest extent a head has, m (an infant's is about 0.12).
pub const MIN_HEAD_M: f64 = 0.08;
/// The largest, m (an adult's with the neck is about 0.3; a helmet-sized margin above).
pub const MAX_HEAD_M: f64 = 0.5;

/// A surface format.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Format {
    /// STL, binary or ASCII.
    Stl,
    /// Wavefront OBJ.
    Obj,
    /// PLY, ASCII or binary.
    Ply,
    /// GIfTI surface.
    Gifti,
    /// FreeSurfer binary triangle surface.
    FreeSurfer,
    /// A NIfTI-1 volume (`.nii`, `.nii.gz`): a T1 MRI whose scalp `mocomp-mri` segments; no
    /// surface to decode here.
    Nifti,
}

impl Format {
    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Stl => "STL",
            Self::Obj => "OBJ",
            Self::Ply => "PLY",
            Self::Gifti => "GIfTI",
            Self::FreeSurfer => "FreeSurfer surface",
            Self::Nifti => "NIfTI volume",
        }
    }

    /// The unit the format fixes, if it fixes one.
    pub fn unit(self) -> Option<LengthUnit> {
        match self {
            Self::Gifti | Self::FreeSurfer => Some(LengthUnit::Millimetre),
            // A NIfTI header states its own unit (or does not): the volume reader says which.
            Self::Stl | Self::Obj | Self::Ply | Self::Nifti => None,
        }
    }

    /// The format of `bytes` named `file`: FreeSurfer's magic number first (its files often
    /// have no extension), then the extension.
    pub fn detect(file: &str, bytes: &[u8]) -> Result<Self, HeadError> {
        if bytes.starts_with(&freesurfer::MAGIC) {
            return Ok(Self::FreeSurfer);
        }
        let lower = file.to_ascii_lowercase();
        if lower.ends_with(".nii") || lower.ends_with(".nii.gz") {
            return Ok(Self::Nifti);
        }
        let ext = lower.rsplit('.').next().unwrap_or("");
        match ext {
            "stl" => Ok(Self::Stl),
            "obj" => Ok(Self::Obj),
            "ply" => Ok(Self::Ply),
            "gii" => Ok(Self::Gifti),
            _ => Err(HeadError::format(
                file,
                "not a head file mocomp reads (.stl, .obj, .ply, .gii, a FreeSurfer surface, or a \
                 NIfTI T1 .nii/.nii.gz)",
                None,
            )),
        }
    }
}

/// A surface as read: in metres, in the frame the file states.
#[derive(Debug, Clone)]
pub struct ReadSurface {
    /// The mesh, metres, as the file has it (not yet repaired).
    pub mesh: Mesh,
    /// Its format.
    pub format: Format,
    /// The unit its numbers were in.
    pub unit: LengthUnit,
    /// Whether that unit came from the format (true) or from the caller.
    pub unit_from_format: bool,
    /// The frame the coordinates are in, as the file says (or that it does not).
    pub frame: String,
}

/// Decodes `bytes` (the file `file`) in `unit` when the format has none; checks the head's size.
pub fn read_surface(
    file: &str,
    bytes: &[u8],
    unit: Option<LengthUnit>,
) -> Result<ReadSurface, HeadError> {
    let (format, mesh, frame) = decode(file, bytes)?;
    let extent = mesh.bounds().map_or(0.0, |b| b.extent());
    let (unit, from_format) = match (format.unit(), unit) {
        (Some(u), _) => (u, true),
        (None, Some(u)) => (u, false),
        (None, None) => {
            let hint = if (MIN_HEAD_M * 1e3..=MAX_HEAD_M * 1e3).contains(&extent) {
                "a head in millimetres"
            } else if (MIN_HEAD_M..=MAX_HEAD_M).contains(&extent) {
                "a head in metres"
            } else {
                "not a head in either"
            };
            return Err(HeadError::UnitsNeeded {
                file: file.into(),
                format: format.name(),
                extent,
                hint,
            });
        }
    };
    let scale = match unit {
        LengthUnit::Metre => 1.0,
        LengthUnit::Millimetre => 1e-3,
    };
    check_size(file, extent * scale, unit)?;
    Ok(ReadSurface {
        mesh: mesh.scaled(scale),
        format,
        unit,
        unit_from_format: from_format,
        frame,
    })
}

/// The surface in `bytes` (the file `file`) as its numbers are, in its format, and the frame it
/// says they are in.
fn decode(file: &str, bytes: &[u8]) -> Result<(Format, Mesh, String), HeadError> {
    let format = Format::detect(file, bytes)?;
    let (mesh, frame) = match format {
        Format::Stl => (
            stl::read(file, bytes)?,
            "not stated (STL has no frame)".to_string(),
        ),
        Format::Obj => (
            obj::read(file, bytes)?,
            "not stated (OBJ has no frame)".to_string(),
        ),
        Format::Ply => (
            ply::read(file, bytes)?,
            "not stated (PLY has no frame)".to_string(),
        ),
        Format::Gifti => gifti::read(file, bytes)?,
        Format::FreeSurfer => freesurfer::read(file, bytes)?,
        Format::Nifti => {
            return Err(HeadError::format(
                file,
                "a volume, not a surface: its scalp is segmented (mocomp-mri), not decoded",
                None,
            ));
        }
    };
    Ok((format, mesh, frame))
}

/// The smallest and largest a coil's casing may measure across, m: a TMS coil's casing spans a
/// few centimetres (a small round coil) to a few decimetres (a figure-of-eight with its handle).
pub const CASING_ACROSS_M: (f64, f64) = (0.01, 0.6);

/// A coil's casing from `bytes` (the file `file`: any surface format), its numbers in `unit`
/// where the format has none (SimNIBS draws casings in millimetres), in the coil's frame.
pub fn read_casing(file: &str, bytes: &[u8], unit: LengthUnit) -> Result<Casing, HeadError> {
    let (format, mesh, _) = decode(file, bytes)?;
    let unit = format.unit().unwrap_or(unit);
    let scale = match unit {
        LengthUnit::Metre => 1.0,
        LengthUnit::Millimetre => 1e-3,
    };
    let mesh = mesh.scaled(scale);
    let across = mesh.bounds().map_or(0.0, |b| b.extent());
    let (least, most) = CASING_ACROSS_M;
    if !(least..=most).contains(&across) {
        return Err(HeadError::BadCasing {
            file: file.into(),
            why: format!(
                "{:.1} mm across, read in {}: a coil's casing measures {:.0} to {:.0} mm (another unit?)",
                across * 1e3,
                unit_name(unit),
                least * 1e3,
                most * 1e3
            ),
        });
    }
    Casing::new(&mesh.vertices, file)
}

/// The unit's name as files and the command line spell it.
pub fn unit_name(u: LengthUnit) -> &'static str {
    match u {
        LengthUnit::Metre => "m",
        LengthUnit::Millimetre => "mm",
    }
}

/// Parses `mm` or `m`.
pub fn parse_unit(s: &str) -> Result<LengthUnit, String> {
    match s {
        "mm" => Ok(LengthUnit::Millimetre),
        "m" => Ok(LengthUnit::Metre),
        _ => Err(format!("{s:?}: a length unit is mm or m")),
    }
}

/// A head `extent_m` across (read in `unit`) is the size of a head, or the error that says
/// what the unit would have to be.
pub fn check_size(file: &str, extent_m: f64, unit: LengthUnit) -> Result<(), HeadError> {
    if (MIN_HEAD_M..=MAX_HEAD_M).contains(&extent_m) {
        return Ok(());
    }
    let hint = match unit {
        LengthUnit::Metre if (MIN_HEAD_M..=MAX_HEAD_M).contains(&(extent_m * 1e-3)) => {
            "the numbers are millimetres read as metres: give --units mm"
        }
        LengthUnit::Millimetre if (MIN_HEAD_M..=MAX_HEAD_M).contains(&(extent_m * 1e3)) => {
            "the numbers are metres read as millimetres: give --units m"
        }
        _ => "this is not a head",
    };
    Err(HeadError::NotHeadSized {
        file: file.into(),
        extent_m,
        unit: unit_name(unit),
        min: MIN_HEAD_M,
        max: MAX_HEAD_M,
        hint,
    })
}

/// A declared count within its limit and within what `available` bytes can hold at
/// `bytes_each`, checked before allocating.
pub(crate) fn check_count(
    file: &str,
    what: &'static str,
    count: u64,
    limit: u64,
    available: Option<(u64, u64)>,
) -> Result<usize, HeadError> {
    if count > limit {
        return Err(HeadError::TooLarge {
            file: file.into(),
            what,
            count,
            limit,
        });
    }
    if let Some((bytes, each)) = available
        && count.saturating_mul(each) > bytes
    {
        return Err(HeadError::format(
            file,
            format!(
                "it declares {count} {what} ({} bytes), but {bytes} bytes follow: truncated",
                count.saturating_mul(each)
            ),
            None,
        ));
    }
    usize::try_from(count).map_err(|_| HeadError::TooLarge {
        file: file.into(),
        what,
        count,
        limit,
    })
}

#[cfg(test)]
mod tests;
