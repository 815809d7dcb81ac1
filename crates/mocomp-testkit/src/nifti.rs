//! NIfTI-1 volumes made byte by byte (the header's fields at their offsets): phantoms for the
//! tests of what reads an MRI, good and spoiled.

/// A NIfTI-1 file (little-endian, single file, no extensions).
#[derive(Debug, Clone, PartialEq)]
pub struct Nifti {
    /// `dim`: the number of dimensions, then each's size.
    pub dim: [i16; 8],
    /// `datatype` (2: uint8).
    pub datatype: i16,
    /// `bitpix`.
    pub bitpix: i16,
    /// `pixdim`: `qfac`, then each voxel's size.
    pub pixdim: [f32; 8],
    /// `xyzt_units` (2: millimetres).
    pub xyzt_units: u8,
    /// The sform's three rows (voxel to RAS), when set (`sform_code` 1).
    pub sform: Option<[[f32; 4]; 3]>,
    /// The voxels, as stored.
    pub data: Vec<u8>,
}

impl Nifti {
    /// `n`³ voxels of `voxel_mm`, uint8, millimetres, sform at the volume's centre.
    pub fn cube(n: usize, voxel_mm: f32, mut value: impl FnMut([f32; 3]) -> u8) -> Self {
        let c = (n as f32 - 1.0) / 2.0;
        let mut data = Vec::with_capacity(n * n * n);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    data.push(value([i, j, k].map(|x| (x as f32 - c) * voxel_mm)));
                }
            }
        }
        let off = -c * voxel_mm;
        Self {
            dim: [3, n as i16, n as i16, n as i16, 1, 1, 1, 1],
            datatype: 2,
            bitpix: 8,
            pixdim: [1.0, voxel_mm, voxel_mm, voxel_mm, 0.0, 0.0, 0.0, 0.0],
            xyzt_units: 2,
            sform: Some([
                [voxel_mm, 0.0, 0.0, off],
                [0.0, voxel_mm, 0.0, off],
                [0.0, 0.0, voxel_mm, off],
            ]),
            data,
        }
    }

    /// The file's bytes.
    pub fn bytes(&self) -> Vec<u8> {
        let mut h = vec![0u8; 352];
        let put = |h: &mut Vec<u8>, at: usize, b: &[u8]| h[at..at + b.len()].copy_from_slice(b);
        put(&mut h, 0, &348i32.to_le_bytes());
        for (i, d) in self.dim.iter().enumerate() {
            put(&mut h, 40 + 2 * i, &d.to_le_bytes());
        }
        put(&mut h, 70, &self.datatype.to_le_bytes());
        put(&mut h, 72, &self.bitpix.to_le_bytes());
        for (i, p) in self.pixdim.iter().enumerate() {
            put(&mut h, 76 + 4 * i, &p.to_le_bytes());
        }
        put(&mut h, 108, &352f32.to_le_bytes());
        h[123] = self.xyzt_units;
        if let Some(rows) = self.sform {
            put(&mut h, 254, &1i16.to_le_bytes());
            for (r, row) in rows.iter().enumerate() {
                for (c, v) in row.iter().enumerate() {
                    put(&mut h, 280 + 16 * r + 4 * c, &v.to_le_bytes());
                }
            }
        }
        put(&mut h, 344, b"n+1\0");
        h.extend_from_slice(&self.data);
        h
    }
}
