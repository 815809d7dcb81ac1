//! A NIfTI-1 volume (`.nii`, or gzipped `.nii.gz`) decoded from bytes: its intensities as `f32`
//! (scaled by `scl_slope`/`scl_inter` as the standard says), and the affine from voxel indices to
//! the image's own RAS frame in metres, from its sform, else its qform, else its voxel size.
//!
//! The header is read first and every size it declares is checked (voxels against
//! [`MAX_VOXELS`], the extensions against [`MAX_VOX_OFFSET`]) before anything is allocated or
//! decompressed for it. Units come from `xyzt_units`; a header that does not state them needs
//! the caller to, and the error says which unit the voxel size suggests.

use crate::error::MriError;
use flate2::read::GzDecoder;
use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::{Matrix3, Matrix4, Point3, Quaternion, UnitQuaternion, Vector3};
use nifti::volume::ndarray::IntoNdArray;
use nifti::{InMemNiftiVolume, NiftiError, NiftiHeader, NiftiType};
use std::io::Read;

/// The most voxels a head volume may have: 40 M is a 0.8 mm whole head (256 × 320 × 320) with
/// room; segmenting one takes about 17 bytes a voxel.
pub const MAX_VOXELS: u64 = 40_000_000;

/// Where the voxels may start at the latest, bytes (the header's extensions come before).
pub const MAX_VOX_OFFSET: f32 = 64.0 * 1024.0 * 1024.0;

/// The NIfTI-1 header's size, bytes.
const HEADER_BYTES: u64 = 348;

/// A volume as read.
#[derive(Debug, Clone)]
pub struct Volume {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// Intensities, i fastest, then j, then k; non-finite voxels are the least finite value
    /// (no data is background, never head).
    pub data: Vec<f32>,
    /// Voxel indices (i, j, k, 1) to the image's RAS frame, metres.
    pub ras_from_voxel: Matrix4<f64>,
    /// The frame, as the header states it.
    pub frame: String,
    /// The unit the header's lengths are in.
    pub unit: LengthUnit,
    /// Whether the header stated it (false: the caller gave it).
    pub unit_from_file: bool,
}

impl Volume {
    /// The voxel's edge along i, j and k, metres.
    pub fn voxel_m(&self) -> [f64; 3] {
        let m = self.ras_from_voxel.fixed_view::<3, 3>(0, 0);
        [m.column(0).norm(), m.column(1).norm(), m.column(2).norm()]
    }

    /// The voxel axis (0, 1 or 2) nearest the image's superior (+S) direction: the normal of
    /// its axial slices.
    pub fn axial_axis(&self) -> usize {
        let m = self.ras_from_voxel.fixed_view::<3, 3>(0, 0);
        (0..3)
            .max_by(|&a, &b| {
                let s = |c: usize| (m[(2, c)] / m.column(c).norm()).abs();
                s(a).total_cmp(&s(b))
            })
            .unwrap_or(2)
    }

    /// The point at (fractional) voxel indices, metres in the image's frame.
    pub fn ras_at(&self, ijk: [f64; 3]) -> Point3<f64> {
        let p =
            self.ras_from_voxel * mocomp_geom::nalgebra::Vector4::new(ijk[0], ijk[1], ijk[2], 1.0);
        Point3::new(p.x, p.y, p.z)
    }
}

/// Decodes the NIfTI-1 file `bytes` (named `file`; gzipped or not), in `unit` when its header
/// does not state one.
pub fn read_volume(file: &str, bytes: &[u8], unit: Option<LengthUnit>) -> Result<Volume, MriError> {
    let mut reader: Box<dyn Read + '_> = if bytes.starts_with(&[0x1f, 0x8b]) {
        Box::new(GzDecoder::new(bytes))
    } else {
        Box::new(bytes)
    };
    let header = NiftiHeader::from_reader(&mut reader)
        .map_err(|e| nifti_error(file, "not a NIfTI-1 header in the first 348 bytes", e))?;
    let dims = check_dims(file, &header)?;
    check_data_type(file, &header)?;
    let (unit, unit_from_file) = spatial_unit(file, &header, unit)?;
    let scale = match unit {
        LengthUnit::Metre => 1.0,
        LengthUnit::Millimetre => 1e-3,
    };
    let (ras, mut frame) = ras_from_voxel(file, &header)?;
    if !unit_from_file && header.xyzt_units & 0x07 != 0 {
        frame.push_str(&format!(
            "; xyzt_units {} overridden by the unit given",
            header.xyzt_units & 0x07
        ));
    }
    let ras_from_voxel = scaled(&ras, scale);
    if !(header.vox_offset.is_finite()
        && header.vox_offset >= HEADER_BYTES as f32
        && header.vox_offset <= MAX_VOX_OFFSET)
    {
        return Err(header_error(
            "vox_offset",
            header.vox_offset,
            file,
            format!("the voxels start at byte 348 or later, before byte {MAX_VOX_OFFSET}"),
        ));
    }
    let skip = header.vox_offset as u64 - HEADER_BYTES;
    let skipped = std::io::copy(&mut (&mut reader).take(skip), &mut std::io::sink())
        .map_err(|e| nifti_error(file, "cannot read the header's extensions", e.into()))?;
    if skipped != skip {
        return Err(truncated(
            file,
            HEADER_BYTES + skipped,
            header.vox_offset as u64,
        ));
    }
    let mut scaled_header = header.clone();
    if !scaled_header.scl_slope.is_finite() {
        // NaN or infinite slope: the standard's "no scaling" (nibabel writes NaN).
        scaled_header.scl_slope = 0.0;
    } else if scaled_header.scl_slope != 0.0 && !scaled_header.scl_inter.is_finite() {
        return Err(header_error(
            "scl_inter",
            scaled_header.scl_inter,
            file,
            "the intercept of a scaled volume must be finite".into(),
        ));
    }
    let volume =
        InMemNiftiVolume::from_reader(&mut reader, &scaled_header).map_err(|e| match e {
            NiftiError::IncompatibleLength(got, expected) => MriError::Nifti {
                file: file.into(),
                what: format!(
                    "truncated: the voxels need {expected} bytes from byte {}, but {got} follow",
                    header.vox_offset
                ),
                source: e,
            },
            e => nifti_error(file, "cannot read the voxels", e),
        })?;
    let array = volume
        .into_ndarray::<f32>()
        .map_err(|e| nifti_error(file, "cannot convert the voxels to numbers", e))?;
    // Reversing the axes makes the iteration i-fastest, the layout NIfTI stores and the
    // isosurface expects.
    let mut data: Vec<f32> = array.t().iter().copied().collect();
    let least = data
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .reduce(f32::min)
        .ok_or_else(|| MriError::NoHead {
            file: file.into(),
            why: "no voxel holds a finite intensity".into(),
        })?;
    for v in data.iter_mut().filter(|v| !v.is_finite()) {
        *v = least;
    }
    Ok(Volume {
        dims,
        data,
        ras_from_voxel,
        frame,
        unit,
        unit_from_file,
    })
}

fn nifti_error(file: &str, what: &str, source: NiftiError) -> MriError {
    MriError::Nifti {
        file: file.into(),
        what: format!("{what} ({source})"),
        source,
    }
}

fn header_error(
    field: &'static str,
    value: impl std::fmt::Display,
    file: &str,
    why: String,
) -> MriError {
    MriError::Header {
        file: file.into(),
        field,
        value: value.to_string(),
        why,
    }
}

fn truncated(file: &str, at: u64, needed: u64) -> MriError {
    MriError::Header {
        file: file.into(),
        field: "vox_offset",
        value: needed.to_string(),
        why: format!("the file ends at byte {at}, before its voxels start: truncated"),
    }
}

/// The volume's three spatial dimensions, checked: 3-D (a 4-D file with one volume is one),
/// at least 2 voxels each way, at most [`MAX_VOXELS`] in all.
fn check_dims(file: &str, h: &NiftiHeader) -> Result<[usize; 3], MriError> {
    let d = h.dim;
    let rank = usize::from(d[0]);
    // dim[4..=rank]: the dimensions past the third, each 1 in a single volume.
    let one_volume = d[4..].iter().take(rank.saturating_sub(3)).all(|&n| n <= 1);
    if !(3..=7).contains(&rank) || !one_volume {
        return Err(header_error(
            "dim",
            format!("{d:?}"),
            file,
            "a head is one 3-D volume (dim[0] = 3, or more with the extra dimensions 1)".into(),
        ));
    }
    let dims = [usize::from(d[1]), usize::from(d[2]), usize::from(d[3])];
    if dims.iter().any(|&n| n < 2) {
        return Err(header_error(
            "dim",
            format!("{d:?}"),
            file,
            "each of the three spatial dimensions needs 2 voxels or more".into(),
        ));
    }
    let voxels = dims.iter().map(|&n| n as u64).product::<u64>();
    if voxels > MAX_VOXELS {
        return Err(MriError::TooLarge {
            file: file.into(),
            dims,
            voxels,
            limit: MAX_VOXELS,
        });
    }
    Ok(dims)
}

fn check_data_type(file: &str, h: &NiftiHeader) -> Result<(), MriError> {
    let t = h
        .data_type()
        .map_err(|e| nifti_error(file, "header field datatype names no NIfTI type", e))?;
    match t {
        NiftiType::Uint8
        | NiftiType::Int8
        | NiftiType::Uint16
        | NiftiType::Int16
        | NiftiType::Uint32
        | NiftiType::Int32
        | NiftiType::Uint64
        | NiftiType::Int64
        | NiftiType::Float32
        | NiftiType::Float64 => {
            // The reader sizes the voxel data by bitpix and reads it by datatype: a header where
            // they disagree would be read past what it sized (a panic in the nifti crate).
            let bits = 8 * t.size_of();
            if usize::try_from(h.bitpix).ok() == Some(bits) {
                Ok(())
            } else {
                Err(header_error(
                    "bitpix",
                    h.bitpix,
                    file,
                    format!("datatype {} ({t:?}) has {bits} bits a voxel", h.datatype),
                ))
            }
        }
        other => Err(header_error(
            "datatype",
            format!("{} ({other:?})", h.datatype),
            file,
            "a T1 holds one real number a voxel (integers or floats), not colour or complex".into(),
        )),
    }
}

/// The spatial unit: the caller's when given, else the header's (`xyzt_units` & 7: 1 m, 2 mm,
/// 3 µm).
fn spatial_unit(
    file: &str,
    h: &NiftiHeader,
    given: Option<LengthUnit>,
) -> Result<(LengthUnit, bool), MriError> {
    let stated = match h.xyzt_units & 0x07 {
        0 => None,
        1 => Some(LengthUnit::Metre),
        2 => Some(LengthUnit::Millimetre),
        code => {
            return Err(header_error(
                "xyzt_units",
                code,
                file,
                "micrometre voxels are a microscope's, not a head MRI's".into(),
            ));
        }
    };
    match (stated, given) {
        // The operator's word over the header's: a header written with the wrong unit is
        // common, and the size check names it; the frame says it was overridden.
        (Some(_), Some(g)) => Ok((g, false)),
        (Some(s), None) => Ok((s, true)),
        (None, Some(g)) => Ok((g, false)),
        (None, None) => {
            let voxel = h.pixdim[1..4]
                .iter()
                .map(|v| f64::from(v.abs()))
                .fold(0.0, f64::max);
            let hint = if (0.1..=10.0).contains(&voxel) {
                "an MRI voxel in millimetres"
            } else if (1e-4..=1e-2).contains(&voxel) {
                "an MRI voxel in metres"
            } else {
                "an MRI voxel in neither"
            };
            Err(MriError::UnitsNeeded {
                file: file.into(),
                code: h.xyzt_units,
                voxel,
                hint,
            })
        }
    }
}

/// The header's affine to its RAS frame (in its own unit) and the frame's name: the sform when
/// its code is set, else the qform, else the voxel size alone (NIfTI's "method 1").
fn ras_from_voxel(file: &str, h: &NiftiHeader) -> Result<(Matrix4<f64>, String), MriError> {
    let named = |code: i16| match code {
        1 => "scanner",
        2 => "aligned to another scan",
        3 => "Talairach",
        4 => "MNI152",
        5 => "a template",
        _ => "unnamed",
    };
    let m = if h.sform_code > 0 {
        let r = |row: [f32; 4]| row.map(f64::from);
        let (x, y, z) = (r(h.srow_x), r(h.srow_y), r(h.srow_z));
        let m = Matrix4::new(
            x[0], x[1], x[2], x[3], y[0], y[1], y[2], y[3], z[0], z[1], z[2], z[3], 0.0, 0.0, 0.0,
            1.0,
        );
        (
            m,
            format!(
                "the sform's RAS ({}, sform_code {})",
                named(h.sform_code),
                h.sform_code
            ),
        )
    } else if h.qform_code > 0 {
        (
            qform(h),
            format!(
                "the qform's RAS ({}, qform_code {})",
                named(h.qform_code),
                h.qform_code
            ),
        )
    } else {
        let p = |i: usize| f64::from(h.pixdim[i]);
        (
            Matrix4::new_nonuniform_scaling(&Vector3::new(p(1), p(2), p(3))),
            "voxel indices scaled by pixdim (the header has neither sform nor qform)".into(),
        )
    };
    let linear: Matrix3<f64> = m.0.fixed_view::<3, 3>(0, 0).into_owned();
    let det = linear.determinant();
    if !m.0.iter().all(|v| v.is_finite()) || !det.is_finite() || det.abs() < 1e-12 {
        let field = if h.sform_code > 0 {
            "srow_x/srow_y/srow_z"
        } else if h.qform_code > 0 {
            "quatern_b/c/d, pixdim"
        } else {
            "pixdim"
        };
        return Err(header_error(
            field,
            format!("{:?}", m.0.fixed_view::<3, 4>(0, 0)),
            file,
            "the voxel-to-RAS affine is not finite or collapses a dimension".into(),
        ));
    }
    Ok(m)
}

/// The qform's affine: rotation from the quaternion (b, c, d; a from unit norm), voxel size from
/// pixdim, the k axis flipped when pixdim[0] (qfac) is −1.
fn qform(h: &NiftiHeader) -> Matrix4<f64> {
    let (b, c, d) = (
        f64::from(h.quatern_b),
        f64::from(h.quatern_c),
        f64::from(h.quatern_d),
    );
    let a = (1.0 - (b * b + c * c + d * d)).max(0.0).sqrt();
    let r = UnitQuaternion::from_quaternion(Quaternion::new(a, b, c, d)).to_rotation_matrix();
    let qfac = if h.pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    let s = Vector3::new(
        f64::from(h.pixdim[1]),
        f64::from(h.pixdim[2]),
        qfac * f64::from(h.pixdim[3]),
    );
    let mut m = Matrix4::identity();
    m.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(r.matrix() * Matrix3::from_diagonal(&s)));
    m[(0, 3)] = f64::from(h.quatern_x);
    m[(1, 3)] = f64::from(h.quatern_y);
    m[(2, 3)] = f64::from(h.quatern_z);
    m
}

/// `m` with its lengths (linear part and offset) multiplied by `s`.
fn scaled(m: &Matrix4<f64>, s: f64) -> Matrix4<f64> {
    let mut out = *m;
    out.fixed_view_mut::<3, 4>(0, 0).scale_mut(s);
    out
}
