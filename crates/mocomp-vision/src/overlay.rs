//! An overlay image per frame, like the seed paper's Fig. 5–7: the IR image in grey, the scan
//! area in yellow, every blob's bounding box (green: identified fiducial, cyan: candidate not
//! identified, red with a cross: rejected), identified fiducials numbered.

use crate::blobs::Frame;
use crate::pipeline::{BlobStatus, FrameResult};

/// An RGB image, 8 bits per channel, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct RgbImage {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `3·width·height` bytes.
    pub data: Vec<u8>,
}

impl RgbImage {
    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.width && (y as u32) < self.height {
            let i = 3 * (y as usize * self.width as usize + x as usize);
            self.data[i..i + 3].copy_from_slice(&c);
        }
    }

    fn rect(&mut self, x0: i64, y0: i64, x1: i64, y1: i64, c: [u8; 3]) {
        for x in x0..=x1 {
            self.put(x, y0, c);
            self.put(x, y1, c);
        }
        for y in y0..=y1 {
            self.put(x0, y, c);
            self.put(x1, y, c);
        }
    }

    /// The colour at `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }
}

/// 3×5 bitmaps of the digits 0–9 (rows top to bottom, 3 bits each).
const DIGITS: [[u8; 5]; 10] = [
    [7, 5, 5, 5, 7],
    [2, 6, 2, 2, 7],
    [7, 1, 7, 4, 7],
    [7, 1, 7, 1, 7],
    [5, 5, 7, 1, 1],
    [7, 4, 7, 1, 7],
    [7, 4, 7, 5, 7],
    [7, 1, 1, 1, 1],
    [7, 5, 7, 5, 7],
    [7, 5, 7, 1, 7],
];

fn number(img: &mut RgbImage, mut x: i64, y: i64, n: usize, c: [u8; 3]) {
    for ch in n.to_string().bytes() {
        let d = &DIGITS[usize::from(ch - b'0')];
        for (row, bits) in d.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) != 0 {
                    for sy in 0..2 {
                        for sx in 0..2 {
                            img.put(x + 2 * col + sx, y + 2 * row as i64 + sy, c);
                        }
                    }
                }
            }
        }
        x += 8;
    }
}

/// Green for identified fiducials.
pub const FIDUCIAL: [u8; 3] = [0, 255, 0];
/// Cyan for candidates not identified.
pub const CANDIDATE: [u8; 3] = [0, 255, 255];
/// Red for rejected blobs.
pub const REJECTED: [u8; 3] = [255, 0, 0];
/// Yellow for the scan area.
pub const SCAN_AREA: [u8; 3] = [255, 255, 0];

/// Draws the overlay of one processed frame.
pub fn overlay(frame: &Frame<'_>, scan_area: [u32; 4], result: &FrameResult) -> RgbImage {
    let mut img = RgbImage {
        width: frame.width,
        height: frame.height,
        data: Vec::with_capacity(3 * frame.ir.len()),
    };
    for &v in frame.ir {
        // Square-root tone curve: dim scenes stay visible, fiducials stay white.
        let g = ((f64::from(v) / 65_535.0).sqrt() * 255.0) as u8;
        img.data.extend_from_slice(&[g, g, g]);
    }
    let [ax0, ay0, ax1, ay1] = scan_area;
    img.rect(
        i64::from(ax0),
        i64::from(ay0),
        i64::from(ax1) - 1,
        i64::from(ay1) - 1,
        SCAN_AREA,
    );
    for b in &result.blobs {
        let [x0, y0, x1, y1] = b.blob.bbox.map(i64::from);
        let (x0, y0, x1, y1) = (x0 - 2, y0 - 2, x1 + 2, y1 + 2);
        match b.status {
            BlobStatus::Fiducial(k) => {
                img.rect(x0, y0, x1, y1, FIDUCIAL);
                number(&mut img, x1 + 3, y0, k + 1, FIDUCIAL);
            }
            BlobStatus::Unmatched => img.rect(x0, y0, x1, y1, CANDIDATE),
            _ => {
                img.rect(x0, y0, x1, y1, REJECTED);
                let n = (x1 - x0).min(y1 - y0);
                for t in 0..=n {
                    img.put(x0 + t, y0 + t, REJECTED);
                    img.put(x1 - t, y0 + t, REJECTED);
                }
            }
        }
    }
    img
}
