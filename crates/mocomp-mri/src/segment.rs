//! The steps from a T1 volume to the scalp, in order: the threshold, the head's voxels, their
//! surface in the image's frame; and the volume's faces the head reaches, where the scan cuts
//! it off.

use crate::error::MriError;
use crate::mask::Mask;
use crate::mask::{SliceCover, across};
use crate::volume::{Volume, read_volume};
use crate::{SegmentOptions, decimate, surface, threshold};
use mocomp_geom::LengthUnit;
use mocomp_geom::nalgebra::Matrix4;
use mocomp_head::Mesh;
use mocomp_head::inspect::{ScanEdge, Segmentation};

/// The fraction of the volume's face voxels the head may cover: a head meets the edge at the
/// neck (and a tight field of view at the nose or crown), never all around.
const MAX_FACE_COVER: f64 = 0.3;

/// The closing's radius, m: openings narrower than about twice this (an ear canal is 7 mm
/// across) are shut before filling, so the scalp passes over them as a coil would. The model
/// grows into concavities that narrow, never shrinks: the safe side.
pub const CLOSING_M: f64 = 0.004;
/// The most closing passes (a fine volume's voxels are small; the closing's cost grows with them).
const MAX_CLOSING_PASSES: usize = 12;

/// A scalp segmented from a volume.
#[derive(Debug, Clone)]
pub struct Scalp {
    /// The surface, metres, in the image's RAS frame, outward-wound, as segmented (not mended).
    pub mesh: Mesh,
    /// The head's voxels after filling.
    pub mask: Mask,
    /// Voxel indices to the image's RAS frame, metres.
    pub ras_from_voxel: Matrix4<f64>,
    /// The frame, as the header states it.
    pub frame: String,
    /// The unit the header's lengths were in, and whether the header said so.
    pub unit: (LengthUnit, bool),
    /// How it was made.
    pub segmentation: Segmentation,
}

/// Segments the scalp of the T1 volume `bytes` (the NIfTI file `file`), in `unit` when its
/// header does not state one.
pub fn segment(
    file: &str,
    bytes: &[u8],
    unit: Option<LengthUnit>,
    options: &SegmentOptions,
) -> Result<Scalp, MriError> {
    let volume = read_volume(file, bytes, unit)?;
    let (lo, hi) = threshold::range(&volume.data).unwrap_or((0.0, 0.0));
    let (threshold, threshold_from) = choose_threshold(file, &volume, options)?;
    let mut mask = Mask::above(volume.dims, &volume.data, threshold);
    let above_threshold = mask.count();
    let pieces = mask.keep_largest_piece();
    let head_voxels = mask.count();
    check_not_the_whole_volume(file, &mask)?;
    let voxel_m = volume.voxel_m();
    let smallest = voxel_m.iter().copied().fold(f64::INFINITY, f64::min);
    let passes = ((CLOSING_M / smallest).round() as usize).clamp(1, MAX_CLOSING_PASSES);
    mask.close(passes);
    mask.fill_enclosed();
    mask.fill_slices(volume.axial_axis());
    let (mesh, isosurface_triangles) = scalp_mesh(&mask, &volume, options);
    let segmentation = Segmentation {
        dims: volume.dims,
        voxel_mm: voxel_m.map(|v| v * 1e3),
        threshold,
        threshold_from,
        intensity_range: [f64::from(lo), f64::from(hi)],
        above_threshold,
        pieces,
        head_voxels,
        filled_voxels: mask.count() - head_voxels,
        closing_mm: passes as f64 * smallest * 1e3,
        cut_by_scan: cut_by_scan(&mask, &volume),
        isosurface_triangles,
        max_triangles: options.max_triangles,
        smoothing_passes: options.smoothing_passes,
    };
    Ok(Scalp {
        mesh,
        mask,
        ras_from_voxel: volume.ras_from_voxel,
        frame: volume.frame,
        unit: (volume.unit, volume.unit_from_file),
        segmentation,
    })
}

/// The threshold given, or Otsu's, and which; refused when it leaves nothing on one side.
fn choose_threshold(
    file: &str,
    volume: &Volume,
    options: &SegmentOptions,
) -> Result<(f64, &'static str), MriError> {
    let (lo, hi) = threshold::range(&volume.data).unwrap_or((0.0, 0.0));
    let (threshold, from) = match options.threshold {
        Some(t) => (t, "given"),
        None => (
            threshold::otsu(&volume.data).ok_or_else(|| MriError::NoHead {
                file: file.into(),
                why: format!("every voxel holds {lo}: nothing to separate a head from air"),
            })?,
            "otsu",
        ),
    };
    if !(threshold > f64::from(lo) && threshold <= f64::from(hi)) {
        return Err(MriError::NoHead {
            file: file.into(),
            why: format!(
                "no voxel is below the threshold {threshold} and some above it (intensities \
                 {lo}–{hi})"
            ),
        });
    }
    Ok((threshold, from))
}

/// The mask's surface in the image's frame, metres, outward, smoothed and decimated; and how
/// many triangles it had before decimation.
fn scalp_mesh(mask: &Mask, volume: &Volume, options: &SegmentOptions) -> (Mesh, usize) {
    let s = surface::isosurface(mask);
    let mut vertices = s.vertices;
    let mut triangles = s.triangles;
    if volume.ras_from_voxel.fixed_view::<3, 3>(0, 0).determinant() < 0.0 {
        // A left-handed voxel grid (LAS storage) mirrors the winding.
        for t in &mut triangles {
            t.swap(1, 2);
        }
    }
    surface::taubin(&mut vertices, &triangles, options.smoothing_passes);
    let isosurface_triangles = triangles.len();
    let (vertices, triangles) = decimate::decimate(&vertices, &triangles, options.max_triangles);
    let mesh = Mesh {
        vertices: vertices.iter().map(|&v| volume.ras_at(v)).collect(),
        triangles,
    };
    (mesh, isosurface_triangles)
}

/// A piece above the threshold that covers the volume's faces all around is noise or a
/// phantom filling the field of view, not a head against air.
fn check_not_the_whole_volume(file: &str, mask: &Mask) -> Result<(), MriError> {
    let [nx, ny, nz] = mask.dims;
    let (mut on_faces, mut faces) = (0usize, 0usize);
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                if i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny || k + 1 == nz {
                    faces += 1;
                    on_faces += usize::from(mask.inside[i + nx * (j + ny * k)]);
                }
            }
        }
    }
    let cover = on_faces as f64 / faces.max(1) as f64;
    if cover > MAX_FACE_COVER {
        return Err(MriError::NoHead {
            file: file.into(),
            why: format!(
                "the largest piece above the threshold covers {:.0} % of the volume's faces (a \
                 head against air covers under {:.0} %): noise, or the threshold is too low",
                cover * 100.0,
                MAX_FACE_COVER * 100.0
            ),
        });
    }
    Ok(())
}

/// The volume's faces the head's voxels reach, each named by the way it looks in the image's
/// frame, with the patch of the face they cover.
fn cut_by_scan(mask: &Mask, volume: &Volume) -> Vec<ScanEdge> {
    let m = volume.ras_from_voxel.fixed_view::<3, 3>(0, 0);
    let mut edges = Vec::new();
    for axis in 0..3 {
        for (end, outward) in [(0usize, -1.0), (mask.dims[axis] - 1, 1.0)] {
            let cover = mask.on_slice(axis, end);
            if cover.voxels == 0 {
                continue;
            }
            let d = m.column(axis) * outward;
            let ras = (0..3)
                .max_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs()))
                .unwrap_or(2);
            let side = match (ras, d[ras] > 0.0) {
                (0, true) => "right",
                (0, false) => "left",
                (1, true) => "anterior",
                (1, false) => "posterior",
                (_, true) => "superior",
                (_, false) => "inferior",
            };
            edges.push(face_patch(volume, axis, end, outward, cover, side));
        }
    }
    edges
}

/// The rectangle in the face's plane (half a voxel beyond the last slice's centres; spanned by
/// the other two voxel axes, its normal out of the volume) that holds the covered voxels' faces.
/// A sheared grid's face is a parallelogram: the rectangle is the box around it in the plane.
fn face_patch(
    volume: &Volume,
    axis: usize,
    end: usize,
    outward: f64,
    cover: SliceCover,
    side: &'static str,
) -> ScanEdge {
    let m = volume.ras_from_voxel.fixed_view::<3, 3>(0, 0);
    let (u, v) = across(axis);
    let (cu, cv) = (m.column(u).into_owned(), m.column(v).into_owned());
    let normal = cu.cross(&cv);
    let normal = if normal.dot(&(m.column(axis) * outward)) < 0.0 {
        -normal
    } else {
        normal
    };
    let normal = normal.normalize();
    let along = cu.normalize();
    let second = normal.cross(&along);
    let corner = |a: f64, b: f64| {
        let mut ijk = [0.0; 3];
        ijk[axis] = end as f64 + 0.5 * outward;
        ijk[u] = a;
        ijk[v] = b;
        volume.ras_at(ijk)
    };
    let (lo, hi) = (
        cover.lo.map(|x| x as f64 - 0.5),
        cover.hi.map(|x| x as f64 + 0.5),
    );
    let corners = [
        corner(lo[0], lo[1]),
        corner(hi[0], lo[1]),
        corner(lo[0], hi[1]),
        corner(hi[0], hi[1]),
    ];
    let origin = corners[0];
    let (mut min, mut max) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for c in &corners {
        let rel = c - origin;
        for (k, axis) in [along, second].iter().enumerate() {
            let x = rel.dot(axis);
            min[k] = min[k].min(x);
            max[k] = max[k].max(x);
        }
    }
    let centre = origin + along * ((min[0] + max[0]) / 2.0) + second * ((min[1] + max[1]) / 2.0);
    ScanEdge {
        side,
        voxels: cover.voxels,
        centre_m: centre.coords.into(),
        outward: normal.into(),
        along: along.into(),
        half_m: [(max[0] - min[0]) / 2.0, (max[1] - min[1]) / 2.0],
    }
}
