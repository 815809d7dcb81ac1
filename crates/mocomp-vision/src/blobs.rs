//! Steps 2 and 3 of the pipeline in one pass: binarise by the IR threshold, drop pixels whose
//! depth reading is out of range (0 = no reading is kept: fiducials read 0), keep the scan area,
//! and label 8-connected components while gathering area, bounding box and centroids.
//!
//! Labelling works on runs (horizontal stretches of foreground pixels): each row's runs are joined
//! to the previous row's overlapping runs with union-find, and per-run sums are merged into their
//! root at the end. Background is skipped 16 pixels at a time. Scratch buffers are kept between
//! frames, so a steady stream allocates nothing here.

use crate::error::VisionError;
use crate::params::CentroidWeighting;

/// One frame: an IR image and a depth image (mm, 0 = no reading) of the same size, row-major.
#[derive(Debug, Clone, Copy)]
pub struct Frame<'a> {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// IR intensities.
    pub ir: &'a [u16],
    /// Depth, millimetres (0 = no reading).
    pub depth: &'a [u16],
}

impl<'a> Frame<'a> {
    /// A frame from buffers; fails when a buffer's length is not `width·height` or the frame is
    /// empty.
    pub fn new(
        width: u32,
        height: u32,
        ir: &'a [u16],
        depth: &'a [u16],
    ) -> Result<Self, VisionError> {
        let (w, h) = (width as usize, height as usize);
        if w == 0 || h == 0 {
            return Err(VisionError::Empty {
                what: format!("frame ({width}×{height})"),
            });
        }
        for (what, buf) in [("IR image", ir), ("depth image", depth)] {
            if buf.len() != w * h {
                return Err(VisionError::BufferSize {
                    what,
                    len: buf.len(),
                    width: w,
                    height: h,
                });
            }
        }
        Ok(Self {
            width,
            height,
            ir,
            depth,
        })
    }
}

/// A connected component of foreground pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    /// Pixels.
    pub area: u32,
    /// Bounding box `[x0, y0, x1, y1]`, inclusive.
    pub bbox: [u32; 4],
    /// Weighted centroid (pixel index coordinates: pixel centres at integers).
    pub centroid: (f64, f64),
    /// Unweighted centroid (mean pixel position).
    pub centroid_unweighted: (f64, f64),
    /// Brightest IR value.
    pub peak: u16,
    /// The blob touches the scan area's (or image's) border.
    pub touches_edge: bool,
}

/// What separates foreground from background.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gates {
    /// IR threshold.
    pub threshold: u16,
    /// Valid depth range, mm (readings outside are removed; 0 is kept).
    pub depth_range: (u16, u16),
    /// Scan area `[x0, y0, x1, y1)`, already clipped to the image.
    pub area: [u32; 4],
    /// Centroid weights.
    pub weighting: CentroidWeighting,
}

#[derive(Debug, Clone, Copy)]
struct Run {
    x0: u32,
    x1: u32,
}

#[derive(Debug, Clone, Copy, Default)]
struct Acc {
    area: u64,
    sw: u64,
    swx: u64,
    swy: u64,
    sx: u64,
    sy: u64,
    x0: u32,
    y0: u32,
    x1: u32,
    y1: u32,
    peak: u16,
}

impl Acc {
    fn merge(&mut self, o: &Acc) {
        self.area += o.area;
        self.sw += o.sw;
        self.swx += o.swx;
        self.swy += o.swy;
        self.sx += o.sx;
        self.sy += o.sy;
        self.x0 = self.x0.min(o.x0);
        self.y0 = self.y0.min(o.y0);
        self.x1 = self.x1.max(o.x1);
        self.y1 = self.y1.max(o.y1);
        self.peak = self.peak.max(o.peak);
    }
}

/// Reusable labelling state.
#[derive(Debug, Default)]
pub struct Labeler {
    runs: Vec<Run>,
    parent: Vec<u32>,
    acc: Vec<Acc>,
}

#[inline]
fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let p = parent[i as usize];
        parent[i as usize] = parent[p as usize];
        i = p;
    }
    i
}

const CHUNK: usize = 16;

impl Labeler {
    /// A labeler with empty scratch buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// Labels the frame; the blobs are written to `out` (cleared first) in raster order of their
    /// first pixel.
    pub fn label(&mut self, frame: &Frame<'_>, gates: &Gates, out: &mut Vec<Blob>) {
        self.runs.clear();
        self.parent.clear();
        self.acc.clear();
        out.clear();
        let w = frame.width as usize;
        let [ax0, ay0, ax1, ay1] = gates.area;
        let (ax0, ax1) = (ax0 as usize, ax1 as usize);
        let thr = gates.threshold;
        let (dmin, dmax) = gates.depth_range;
        let (mut prev_start, mut prev_end) = (0usize, 0usize);
        for y in ay0..ay1 {
            let base = y as usize * w;
            let ir = &frame.ir[base + ax0..base + ax1];
            let depth = &frame.depth[base + ax0..base + ax1];
            let cur_start = self.runs.len();
            let n = ir.len();
            let pass = |i: usize| {
                let d = depth[i];
                ir[i] >= thr && (d == 0 || (d >= dmin && d <= dmax))
            };
            let mut x = 0usize;
            while x < n {
                if x + CHUNK <= n {
                    let m = ir[x..x + CHUNK].iter().fold(0u16, |a, &b| a.max(b));
                    if m < thr {
                        x += CHUNK;
                        continue;
                    }
                }
                if !pass(x) {
                    x += 1;
                    continue;
                }
                let start = x;
                while x < n && pass(x) {
                    x += 1;
                }
                self.push_run(ir, start, x - 1, ax0 as u32, y, thr, gates.weighting);
            }
            let cur_end = self.runs.len();
            // 8-connectivity: join with previous-row runs overlapping [x0 − 1, x1 + 1].
            let mut p = prev_start;
            for r in cur_start..cur_end {
                let Run { x0, x1 } = self.runs[r];
                while p < prev_end && self.runs[p].x1 + 1 < x0 {
                    p += 1;
                }
                let mut q = p;
                while q < prev_end && self.runs[q].x0 <= x1 + 1 {
                    let (a, b) = (
                        find(&mut self.parent, r as u32),
                        find(&mut self.parent, q as u32),
                    );
                    if a != b {
                        // The earlier run stays root: blobs come out in raster order.
                        let (lo, hi) = if a < b { (a, b) } else { (b, a) };
                        self.parent[hi as usize] = lo;
                    }
                    q += 1;
                }
            }
            prev_start = cur_start;
            prev_end = cur_end;
        }
        // Merge every run into its root, then emit the roots in order.
        for i in 0..self.runs.len() {
            let r = find(&mut self.parent, i as u32) as usize;
            if r != i {
                let a = self.acc[i];
                self.acc[r].merge(&a);
            }
        }
        for i in 0..self.runs.len() {
            if self.parent[i] as usize != i {
                continue;
            }
            let a = &self.acc[i];
            let area = a.area as f64;
            let sw = a.sw as f64;
            out.push(Blob {
                area: a.area as u32,
                bbox: [a.x0, a.y0, a.x1, a.y1],
                centroid: (a.swx as f64 / sw, a.swy as f64 / sw),
                centroid_unweighted: (a.sx as f64 / area, a.sy as f64 / area),
                peak: a.peak,
                touches_edge: a.x0 as usize == ax0
                    || a.x1 as usize + 1 == ax1
                    || a.y0 == ay0
                    || a.y1 + 1 == ay1,
            });
        }
    }

    #[allow(clippy::too_many_arguments)]
    fn push_run(
        &mut self,
        ir: &[u16],
        start: usize,
        end: usize,
        x_offset: u32,
        y: u32,
        thr: u16,
        weighting: CentroidWeighting,
    ) {
        let id = self.runs.len() as u32;
        let (x0, x1) = (x_offset + start as u32, x_offset + end as u32);
        self.runs.push(Run { x0, x1 });
        self.parent.push(id);
        let mut a = Acc {
            x0,
            y0: y,
            x1,
            y1: y,
            ..Acc::default()
        };
        for (k, &v) in ir[start..=end].iter().enumerate() {
            let x = u64::from(x0) + k as u64;
            let wgt = match weighting {
                CentroidWeighting::Binary => 1,
                CentroidWeighting::AboveThreshold => u64::from(v - thr) + 1,
                CentroidWeighting::Intensity => u64::from(v).max(1),
            };
            a.sw += wgt;
            a.swx += wgt * x;
            a.sx += x;
            a.peak = a.peak.max(v);
        }
        let len = u64::from(x1 - x0 + 1);
        a.area = len;
        a.swy = a.sw * u64::from(y);
        a.sy = len * u64::from(y);
        self.acc.push(a);
    }
}

/// The robust depth of a blob (step 4): the median of the valid readings (non-zero, within the
/// range) in a ring `ring` pixels wide just outside its bounding box. Returns the median (mm) and
/// the number of readings, or `None` when fewer than `min_valid` are valid. `scratch` is reused.
pub fn ring_depth(
    frame: &Frame<'_>,
    bbox: [u32; 4],
    ring: u32,
    depth_range: (u16, u16),
    min_valid: u32,
    scratch: &mut Vec<u16>,
) -> Option<(f64, usize)> {
    scratch.clear();
    let w = frame.width;
    let [bx0, by0, bx1, by1] = bbox;
    let x0 = bx0.saturating_sub(ring);
    let y0 = by0.saturating_sub(ring);
    let x1 = (bx1 + ring).min(w - 1);
    let y1 = (by1 + ring).min(frame.height - 1);
    for y in y0..=y1 {
        let row = &frame.depth[(y * w) as usize..((y + 1) * w) as usize];
        let inside_rows = y >= by0 && y <= by1;
        for x in x0..=x1 {
            if inside_rows && x >= bx0 && x <= bx1 {
                continue;
            }
            let d = row[x as usize];
            if d != 0 && d >= depth_range.0 && d <= depth_range.1 {
                scratch.push(d);
            }
        }
    }
    let n = scratch.len();
    if n == 0 || (n as u32) < min_valid {
        return None;
    }
    let mid = n / 2;
    let upper = *scratch.select_nth_unstable(mid).1;
    let median = if n % 2 == 1 {
        f64::from(upper)
    } else {
        let lower = scratch[..mid].iter().copied().max().unwrap_or(upper);
        0.5 * (f64::from(lower) + f64::from(upper))
    };
    Some((median, n))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gates(w: u32, h: u32) -> Gates {
        Gates {
            threshold: 100,
            depth_range: (500, 2000),
            area: [0, 0, w, h],
            weighting: CentroidWeighting::Binary,
        }
    }

    fn blobs(w: u32, h: u32, ir: &[u16], depth: &[u16], g: &Gates) -> Vec<Blob> {
        let f = Frame::new(w, h, ir, depth).unwrap();
        let mut out = Vec::new();
        Labeler::new().label(&f, g, &mut out);
        out
    }

    #[test]
    fn eight_connectivity_joins_diagonals_and_u_shapes() {
        // A diagonal line is one blob with 8-connectivity; a U joins at the bottom.
        let (w, h) = (40u32, 6u32);
        let mut ir = vec![0u16; (w * h) as usize];
        for k in 1..5 {
            ir[(k * w + k) as usize] = 200;
        }
        for y in 1..5 {
            ir[(y * w + 20) as usize] = 200;
            ir[(y * w + 24) as usize] = 200;
        }
        for x in 20..=24 {
            ir[(4 * w + x) as usize] = 200;
        }
        let depth = vec![0u16; ir.len()];
        let b = blobs(w, h, &ir, &depth, &gates(w, h));
        assert_eq!(b.len(), 2, "{b:?}");
        assert_eq!(b[0].area, 4);
        assert_eq!(b[0].bbox, [1, 1, 4, 4]);
        assert_eq!(b[1].area, 3 + 3 + 5);
        assert_eq!(b[1].bbox, [20, 1, 24, 4]);
        assert!((b[0].centroid.0 - 2.5).abs() < 1e-12);
    }

    #[test]
    fn depth_gate_keeps_zero_and_removes_out_of_range() {
        let (w, h) = (20u32, 3u32);
        let mut ir = vec![0u16; 60];
        let mut depth = vec![0u16; 60];
        ir[21] = 300; // depth 0: kept
        ir[25] = 300;
        depth[25] = 300; // too near: removed
        ir[30] = 300;
        depth[30] = 1000; // in range: kept
        let b = blobs(w, h, &ir, &depth, &gates(w, h));
        assert_eq!(b.len(), 2);
        assert_eq!(b[0].bbox[0], 1);
        assert_eq!(b[1].bbox[0], 10);
    }

    #[test]
    fn weighted_centroid_and_edges() {
        let (w, h) = (10u32, 3u32);
        let mut ir = vec![0u16; 30];
        ir[13] = 100;
        ir[14] = 300; // heavier
        ir[0] = 500; // touches the border
        let depth = vec![0u16; 30];
        let mut g = gates(w, h);
        g.weighting = CentroidWeighting::Intensity;
        let b = blobs(w, h, &ir, &depth, &g);
        assert_eq!(b.len(), 2);
        assert!(b[0].touches_edge);
        assert!(!b[1].touches_edge);
        assert!((b[1].centroid.0 - (3.0 * 100.0 + 4.0 * 300.0) / 400.0).abs() < 1e-12);
        assert_eq!(b[1].peak, 300);
        // A scan area makes its own border an edge and hides the rest.
        g.area = [2, 0, 5, 3];
        let b = blobs(w, h, &ir, &depth, &g);
        assert_eq!(b.len(), 1);
        assert!(b[0].touches_edge);
    }

    #[test]
    fn ring_median_skips_invalid_readings() {
        let (w, h) = (9u32, 9u32);
        let ir = vec![0u16; 81];
        let mut depth = vec![1000u16; 81];
        depth[4 * 9 + 4] = 0; // the blob itself reads 0
        depth[0] = 0;
        depth[1] = 9000; // out of range
        depth[2] = 1010;
        let f = Frame::new(w, h, &ir, &depth).unwrap();
        let mut s = Vec::new();
        let (m, n) = ring_depth(&f, [4, 4, 4, 4], 2, (500, 2000), 4, &mut s).unwrap();
        assert_eq!(n, 24);
        assert_eq!(m, 1000.0);
        assert!(ring_depth(&f, [4, 4, 4, 4], 1, (500, 2000), 9, &mut s).is_none());
    }

    #[test]
    fn frame_sizes_are_checked() {
        assert!(matches!(
            Frame::new(4, 4, &[0; 16], &[0; 15]),
            Err(VisionError::BufferSize {
                what: "depth image",
                ..
            })
        ));
        assert!(matches!(
            Frame::new(0, 4, &[], &[]),
            Err(VisionError::Empty { .. })
        ));
    }
}
