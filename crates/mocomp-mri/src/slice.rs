//! Slices of a volume for a screen: planes through a point, aligned with the image's RAS axes
//! (whatever the voxel grid's own orientation), sampled from the voxels by trilinear
//! interpolation, as a navigator shows an MRI. The screen's conventions, which the console's page
//! follows to put a point on a slice:
//! - **axial** (z fixed): right on screen is +x (the patient's right), up is +y (anterior);
//! - **coronal** (y fixed): right +x, up +z (superior);
//! - **sagittal** (x fixed): right +y (anterior), up +z.
//!
//! Each spans the volume's RAS bounding box; pixel `(u, v)` (v down from the top row) has its
//! centre at `origin + step · (u · right − v · up)`.

use crate::volume::Volume;
use mocomp_geom::nalgebra::{Matrix4, Point3, Vector3, Vector4};

/// The most pixels along a slice's side (a hostile step or volume cannot make more).
pub const MAX_SIDE: usize = 2048;

/// A plane of the three a navigator shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    /// z fixed.
    Axial,
    /// y fixed.
    Coronal,
    /// x fixed.
    Sagittal,
}

impl std::str::FromStr for Plane {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "axial" => Ok(Self::Axial),
            "coronal" => Ok(Self::Coronal),
            "sagittal" => Ok(Self::Sagittal),
            _ => Err(format!("plane {s:?}: axial, coronal or sagittal")),
        }
    }
}

impl Plane {
    /// The RAS axes (indices) of the screen's right and up, and the one held fixed.
    pub fn axes(self) -> (usize, usize, usize) {
        match self {
            Self::Axial => (0, 1, 2),
            Self::Coronal => (0, 2, 1),
            Self::Sagittal => (1, 2, 0),
        }
    }
}

/// One slice.
#[derive(Debug, Clone, PartialEq)]
pub struct Slice {
    /// Pixels across.
    pub width: usize,
    /// Pixels down.
    pub height: usize,
    /// Intensities, row by row from the top; outside the volume the volume's least value.
    pub values: Vec<f32>,
    /// The top-left pixel's centre, RAS, m.
    pub origin: Point3<f64>,
    /// The pixel's edge, m.
    pub step_m: f64,
}

/// The volume's voxel centres' RAS bounding box, m.
pub fn bounds(v: &Volume) -> (Point3<f64>, Point3<f64>) {
    let mut lo = Point3::new(f64::INFINITY, f64::INFINITY, f64::INFINITY);
    let mut hi = Point3::new(f64::NEG_INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY);
    for c in 0..8 {
        let ijk = std::array::from_fn(|a| {
            if c & (1 << a) == 0 {
                0.0
            } else {
                v.dims[a].saturating_sub(1) as f64
            }
        });
        let p = v.ras_at(ijk);
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    (lo, hi)
}

/// Samples a volume at RAS points.
#[derive(Debug, Clone)]
pub struct Sampler<'a> {
    volume: &'a Volume,
    voxel_from_ras: Matrix4<f64>,
    background: f32,
}

impl<'a> Sampler<'a> {
    /// A sampler of `volume` (`None` when its affine cannot be inverted).
    pub fn new(volume: &'a Volume) -> Option<Self> {
        let voxel_from_ras = volume.ras_from_voxel.try_inverse()?;
        let background = volume.data.iter().copied().fold(f32::INFINITY, f32::min);
        Some(Self {
            volume,
            voxel_from_ras,
            background: if background.is_finite() {
                background
            } else {
                0.0
            },
        })
    }

    /// The intensity at RAS point `p` (m), trilinear; outside the volume, its least value.
    pub fn at(&self, p: &Point3<f64>) -> f32 {
        let q = self.voxel_from_ras * Vector4::new(p.x, p.y, p.z, 1.0);
        let d = self.volume.dims;
        // A point on the volume's edge may land a rounding error outside it.
        const EDGE: f64 = 1e-6;
        let mut ijk = [q.x, q.y, q.z];
        for a in 0..3 {
            let last = d[a].saturating_sub(1) as f64;
            if !(ijk[a] >= -EDGE && ijk[a] <= last + EDGE) {
                return self.background;
            }
            ijk[a] = ijk[a].clamp(0.0, last);
        }
        let base = ijk.map(|x| (x.floor() as usize).min(usize::MAX - 1));
        let frac: [f64; 3] = std::array::from_fn(|a| ijk[a] - base[a] as f64);
        let mut sum = 0.0f64;
        for c in 0..8usize {
            let mut w = 1.0;
            let mut idx = [0usize; 3];
            for a in 0..3 {
                let up = c & (1 << a) != 0;
                idx[a] = (base[a] + usize::from(up)).min(d[a].saturating_sub(1));
                w *= if up { frac[a] } else { 1.0 - frac[a] };
            }
            if w > 0.0 {
                let i = idx[0] + d[0] * (idx[1] + d[1] * idx[2]);
                sum += w * f64::from(self.volume.data.get(i).copied().unwrap_or(self.background));
            }
        }
        sum as f32
    }

    /// The slice in `plane` through `at` (RAS, m), its pixels `step_m` apart (at least a tenth of
    /// a millimetre, and no more than [`MAX_SIDE`] a side: the step grows to fit).
    pub fn slice(&self, plane: Plane, at: &Point3<f64>, step_m: f64) -> Slice {
        let (lo, hi) = bounds(self.volume);
        let (r, u, f) = plane.axes();
        let span = (hi[r] - lo[r]).max(hi[u] - lo[u]).max(0.0);
        let step = step_m.max(1e-4).max(span / (MAX_SIDE - 1) as f64);
        // (A span a whole number of steps long must not lose its last pixel to rounding.)
        let width = ((hi[r] - lo[r]) / step + 1e-9).floor() as usize + 1;
        let height = ((hi[u] - lo[u]) / step + 1e-9).floor() as usize + 1;
        let mut origin = Point3::origin();
        origin[r] = lo[r];
        origin[u] = hi[u];
        origin[f] = at[f];
        let (right, up) = (unit(r), unit(u));
        let mut values = Vec::with_capacity(width * height);
        for v in 0..height {
            for x in 0..width {
                let p = origin + step * (x as f64 * right - v as f64 * up);
                values.push(self.at(&p));
            }
        }
        Slice {
            width,
            height,
            values,
            origin,
            step_m: step,
        }
    }
}

fn unit(axis: usize) -> Vector3<f64> {
    let mut v = Vector3::zeros();
    v[axis] = 1.0;
    v
}

/// A window for display (`lo`, `hi`): the volume's 1st and 99.5th percentiles, over a sample
/// of a quarter million voxels at most.
pub fn default_window(v: &Volume) -> (f32, f32) {
    let stride = (v.data.len() / 250_000).max(1);
    let mut sample: Vec<f32> = v
        .data
        .iter()
        .step_by(stride)
        .copied()
        .filter(|x| x.is_finite())
        .collect();
    if sample.is_empty() {
        return (0.0, 1.0);
    }
    sample.sort_by(f32::total_cmp);
    let at = |q: f64| sample[((sample.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(0.01), at(0.995));
    if hi > lo { (lo, hi) } else { (lo, lo + 1.0) }
}

/// `values` windowed to grey levels: `lo` and below black, `hi` and above white.
pub fn grey(values: &[f32], lo: f32, hi: f32) -> Vec<u8> {
    let span = (hi - lo).max(f32::EPSILON);
    values
        .iter()
        .map(|x| (((x - lo) / span).clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::LengthUnit;

    /// 20 × 30 × 40 voxels of 2 mm, the grid turned (i along -y, j along +x, k along +z) and
    /// shifted, each voxel's value its RAS x + 2·y + 3·z in mm (linear: trilinear sampling is
    /// exact inside).
    fn volume() -> Volume {
        let ras_from_voxel = Matrix4::new(
            0.0, 0.002, 0.0, -0.03, //
            -0.002, 0.0, 0.0, 0.02, //
            0.0, 0.0, 0.002, -0.04, //
            0.0, 0.0, 0.0, 1.0,
        );
        let dims = [20, 30, 40];
        let mut data = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = ras_from_voxel * Vector4::new(i as f64, j as f64, k as f64, 1.0);
                    data.push(((p.x + 2.0 * p.y + 3.0 * p.z) * 1e3) as f32);
                }
            }
        }
        Volume {
            dims,
            data,
            ras_from_voxel,
            frame: "scanner".into(),
            unit: LengthUnit::Millimetre,
            unit_from_file: true,
        }
    }

    #[test]
    fn each_pixel_is_the_volume_at_the_point_the_conventions_give() {
        let v = volume();
        let s = Sampler::new(&v).unwrap();
        let (lo, hi) = bounds(&v);
        // x from j: -30 … 28 mm; y from i: 20 … -18 mm; z: -40 … 38 mm.
        assert!(
            (lo - Point3::new(-0.03, -0.018, -0.04)).norm() < 1e-12,
            "{lo}"
        );
        assert!(
            (hi - Point3::new(0.028, 0.02, 0.038)).norm() < 1e-12,
            "{hi}"
        );
        let at = Point3::new(0.001, -0.003, 0.005);
        for plane in [Plane::Axial, Plane::Coronal, Plane::Sagittal] {
            let slice = s.slice(plane, &at, 0.001);
            let (r, u, f) = plane.axes();
            assert_eq!(slice.width, ((hi[r] - lo[r]) / 0.001).round() as usize + 1);
            assert_eq!(slice.origin[f], at[f]);
            for (x, y) in [(0, 0), (7, 11), (slice.width - 1, slice.height - 1)] {
                let mut p = slice.origin;
                p[r] += x as f64 * 0.001;
                p[u] -= y as f64 * 0.001;
                let want = (p.x + 2.0 * p.y + 3.0 * p.z) * 1e3;
                let got = f64::from(slice.values[y * slice.width + x]);
                assert!(
                    (got - want).abs() < 1e-3,
                    "{plane:?} ({x}, {y}): {got} {want}"
                );
            }
        }
        // Outside: the least value.
        let least = v.data.iter().copied().fold(f32::INFINITY, f32::min);
        assert_eq!(s.at(&Point3::new(1.0, 0.0, 0.0)), least);
    }

    #[test]
    fn a_huge_volume_or_a_tiny_step_still_makes_a_bounded_slice() {
        let mut v = volume();
        v.ras_from_voxel[(0, 1)] = 1.0; // 1 m voxels along x: a 30 m span
        let s = Sampler::new(&v).unwrap();
        let slice = s.slice(Plane::Axial, &Point3::origin(), 1e-9);
        assert!(
            slice.width <= MAX_SIDE && slice.height <= MAX_SIDE,
            "{} {}",
            slice.width,
            slice.height
        );
        assert_eq!(slice.values.len(), slice.width * slice.height);
    }

    #[test]
    fn the_window_greys_from_black_to_white() {
        assert_eq!(
            grey(&[-5.0, 0.0, 50.0, 100.0, 200.0, f32::NAN], 0.0, 100.0),
            [0, 0, 128, 255, 255, 0]
        );
        let (lo, hi) = default_window(&volume());
        assert!(lo < hi);
    }
}
