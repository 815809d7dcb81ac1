//! The head as a set of voxels: those at or above the threshold, their largest 6-connected piece
//! (the head; noise, the scanner's bed and stray bright voxels are the rest), and everything it
//! encloses filled in — first in 3-D, then in each axial slice, since the spinal canal, the CSF
//! around the brain and the airways reach the volume's edge through the neck in 3-D but are
//! enclosed by skin in every slice.

/// A volume of yes/no voxels, i fastest.
#[derive(Debug, Clone, PartialEq)]
pub struct Mask {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// One a voxel: in the head or not.
    pub inside: Vec<bool>,
}

impl Mask {
    /// The voxels of `data` (dims `dims`) at or above `threshold`.
    pub fn above(dims: [usize; 3], data: &[f32], threshold: f64) -> Self {
        Self {
            dims,
            inside: data.iter().map(|&v| f64::from(v) >= threshold).collect(),
        }
    }

    /// A mask of `dims` whose voxel (i, j, k) is inside when `inside` says so.
    pub fn from_fn(dims: [usize; 3], mut inside: impl FnMut([usize; 3]) -> bool) -> Self {
        let mut v = Vec::with_capacity(dims[0] * dims[1] * dims[2]);
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    v.push(inside([i, j, k]));
                }
            }
        }
        Self { dims, inside: v }
    }

    /// Voxels inside.
    pub fn count(&self) -> usize {
        self.inside.iter().filter(|&&v| v).count()
    }

    fn coords(&self, at: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [at % nx, (at / nx) % ny, at / (nx * ny)]
    }

    /// The 6 face neighbours of voxel `at` that exist.
    fn neighbours(&self, at: usize) -> impl Iterator<Item = usize> + use<> {
        let [nx, ny, nz] = self.dims;
        let [i, j, k] = self.coords(at);
        let plane = nx * ny;
        [
            (i > 0).then(|| at - 1),
            (i + 1 < nx).then(|| at + 1),
            (j > 0).then(|| at - nx),
            (j + 1 < ny).then(|| at + nx),
            (k > 0).then(|| at - plane),
            (k + 1 < nz).then(|| at + plane),
        ]
        .into_iter()
        .flatten()
    }

    /// Keeps only the largest 6-connected piece; returns how many pieces there were.
    pub fn keep_largest_piece(&mut self) -> usize {
        let mut label = vec![0u32; self.inside.len()];
        let mut stack = Vec::new();
        let (mut pieces, mut best) = (0u32, (0usize, 0u32));
        for start in 0..self.inside.len() {
            if !self.inside[start] || label[start] != 0 {
                continue;
            }
            pieces += 1;
            label[start] = pieces;
            stack.push(start);
            let mut size = 0;
            while let Some(at) = stack.pop() {
                size += 1;
                for n in self.neighbours(at) {
                    if self.inside[n] && label[n] == 0 {
                        label[n] = pieces;
                        stack.push(n);
                    }
                }
            }
            if size > best.0 {
                best = (size, pieces);
            }
        }
        for (v, l) in self.inside.iter_mut().zip(&label) {
            *v = *l == best.1 && best.1 != 0;
        }
        pieces as usize
    }

    /// Morphological closing by `passes` voxels (dilation then erosion, each pass alternating
    /// the 6-neighbour cross and the 26-neighbour cube, an octagonal approximation of a ball):
    /// closes openings narrower than about twice that (the ear canals, the gaps the skull base
    /// leaves), so the fill that follows does not leave the surface diving into them. The
    /// volume's faces neither add nor remove: a head cut at the neck stays cut there.
    pub fn close(&mut self, passes: usize) {
        for p in 0..passes {
            self.inside = self.dilated(p % 2 == 1, true);
        }
        for p in 0..passes {
            self.inside = self.dilated(p % 2 == 1, false);
        }
    }

    /// One dilation of the voxels equal to `of` (the cube when `cube`, else the cross);
    /// dilating `false` erodes the mask.
    fn dilated(&self, cube: bool, of: bool) -> Vec<bool> {
        let d = self.dims;
        let stride = [1, d[0], d[0] * d[1]];
        let shifted = |src: &[bool], axis: usize| -> Vec<bool> {
            src.iter()
                .enumerate()
                .map(|(at, &v)| {
                    let c = (at / stride[axis]) % d[axis];
                    v == of
                        || (c > 0 && src[at - stride[axis]] == of)
                        || (c + 1 < d[axis] && src[at + stride[axis]] == of)
                })
                .map(|hit| if hit { of } else { !of })
                .collect()
        };
        if cube {
            // The cube is the three 1-D dilations in turn.
            let x = shifted(&self.inside, 0);
            let y = shifted(&x, 1);
            shifted(&y, 2)
        } else {
            // The cross is their union.
            let (x, y, z) = (
                shifted(&self.inside, 0),
                shifted(&self.inside, 1),
                shifted(&self.inside, 2),
            );
            (0..self.inside.len())
                .map(|at| {
                    if x[at] == of || y[at] == of || z[at] == of {
                        of
                    } else {
                        !of
                    }
                })
                .collect()
        }
    }

    /// Fills what the head encloses in 3-D: every outside voxel not reached from the volume's
    /// faces through outside voxels. Returns the voxels added.
    pub fn fill_enclosed(&mut self) -> usize {
        let [nx, ny, nz] = self.dims;
        let mut reached = vec![false; self.inside.len()];
        let mut stack: Vec<usize> = (0..self.inside.len())
            .filter(|&at| {
                let [i, j, k] = self.coords(at);
                i == 0 || j == 0 || k == 0 || i + 1 == nx || j + 1 == ny || k + 1 == nz
            })
            .filter(|&at| !self.inside[at])
            .collect();
        for &at in &stack {
            reached[at] = true;
        }
        while let Some(at) = stack.pop() {
            for n in self.neighbours(at) {
                if !self.inside[n] && !reached[n] {
                    reached[n] = true;
                    stack.push(n);
                }
            }
        }
        let mut added = 0;
        for (v, r) in self.inside.iter_mut().zip(&reached) {
            if !*v && !*r {
                *v = true;
                added += 1;
            }
        }
        added
    }

    /// The voxels inside on the slice across `axis` (0, 1 or 2) at index `at` along it: how
    /// many, and where.
    pub fn on_slice(&self, axis: usize, at: usize) -> SliceCover {
        let d = self.dims;
        let (u, v) = across(axis);
        let stride = [1, d[0], d[0] * d[1]];
        let w = stride[axis.min(2)];
        let mut cover = SliceCover {
            voxels: 0,
            lo: [usize::MAX; 2],
            hi: [0; 2],
        };
        for b in 0..d[v] {
            for a in 0..d[u] {
                if self.inside[at * w + a * stride[u] + b * stride[v]] {
                    cover.voxels += 1;
                    cover.lo = [cover.lo[0].min(a), cover.lo[1].min(b)];
                    cover.hi = [cover.hi[0].max(a), cover.hi[1].max(b)];
                }
            }
        }
        cover
    }

    /// Fills what the head encloses within each slice across `axis` (0, 1 or 2). Returns the
    /// voxels added.
    pub fn fill_slices(&mut self, axis: usize) -> usize {
        let d = self.dims;
        let (u, v) = across(axis);
        let stride = [1, d[0], d[0] * d[1]];
        let (nu, nv) = (d[u], d[v]);
        let mut slice = vec![false; nu * nv];
        let mut added = 0;
        for s in 0..d[axis.min(2)] {
            let at = |a: usize, b: usize| s * stride[axis.min(2)] + a * stride[u] + b * stride[v];
            for b in 0..nv {
                for a in 0..nu {
                    slice[a + nu * b] = self.inside[at(a, b)];
                }
            }
            let filled = fill_2d(&slice, nu, nv);
            for b in 0..nv {
                for a in 0..nu {
                    if filled[a + nu * b] && !slice[a + nu * b] {
                        self.inside[at(a, b)] = true;
                        added += 1;
                    }
                }
            }
        }
        added
    }
}

/// The voxels inside on one slice (see [`Mask::on_slice`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SliceCover {
    /// How many.
    pub voxels: usize,
    /// The least index along the slice's two axes (the other two voxel axes, in order);
    /// meaningless when there are none.
    pub lo: [usize; 2],
    /// The greatest.
    pub hi: [usize; 2],
}

/// The two axes that span a slice across `axis`, in order (the third for anything past 2).
pub fn across(axis: usize) -> (usize, usize) {
    match axis {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    }
}

/// `inside` (nu × nv, a fastest) with every outside pixel not 4-connected to the border through
/// outside pixels made inside.
fn fill_2d(inside: &[bool], nu: usize, nv: usize) -> Vec<bool> {
    let mut reached = vec![false; inside.len()];
    let mut stack: Vec<usize> = (0..inside.len())
        .filter(|&p| {
            let (a, b) = (p % nu, p / nu);
            (a == 0 || b == 0 || a + 1 == nu || b + 1 == nv) && !inside[p]
        })
        .collect();
    for &p in &stack {
        reached[p] = true;
    }
    while let Some(p) = stack.pop() {
        let (a, b) = (p % nu, p / nu);
        let next = [
            (a > 0).then(|| p - 1),
            (a + 1 < nu).then(|| p + 1),
            (b > 0).then(|| p - nu),
            (b + 1 < nv).then(|| p + nu),
        ];
        for n in next.into_iter().flatten() {
            if !inside[n] && !reached[n] {
                reached[n] = true;
                stack.push(n);
            }
        }
    }
    inside
        .iter()
        .zip(&reached)
        .map(|(&i, &r)| i || !r)
        .collect()
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A cube of `n` voxels with a hollow ball of radius `r_out` (shell `wall` thick) at its
    /// centre, a tube from the hollow down to the bottom face when `tube`, and a stray voxel.
    fn hollow_ball(n: usize, r_out: f64, wall: f64, tube: bool) -> Mask {
        let c = (n as f64 - 1.0) / 2.0;
        let mut m = Mask::from_fn([n; 3], |p| {
            let [x, y, z] = p.map(|v| v as f64 - c);
            let d = (x * x + y * y + z * z).sqrt();
            let in_tube = tube && x.abs() < 1.5 && y.abs() < 1.5 && z < 0.0;
            d <= r_out && d > r_out - wall && !in_tube
        });
        m.inside[1 + n * (1 + n)] = true;
        m
    }

    #[test]
    fn closing_shuts_a_narrow_channel_and_keeps_the_outline() {
        // A block with a 2-voxel slot cut into it from one side.
        let n = 20;
        let mut inside = vec![false; n * n * n];
        for k in 4..16 {
            for j in 4..16 {
                for i in 4..16 {
                    let slot = (9..11).contains(&j) && i < 12 && (6..14).contains(&k);
                    inside[i + n * (j + n * k)] = !slot;
                }
            }
        }
        let mut m = Mask {
            dims: [n, n, n],
            inside: inside.clone(),
        };
        m.close(2);
        assert!(m.inside[6 + n * (9 + n * 10)], "the slot is closed");
        // Nothing outside the block's box is added, nothing of the block lost.
        for (at, (&before, &after)) in inside.iter().zip(&m.inside).enumerate() {
            let [i, j, k] = m.coords(at);
            let in_box = (4..16).contains(&i) && (4..16).contains(&j) && (4..16).contains(&k);
            assert!(!before || after, "lost {i} {j} {k}");
            assert!(in_box || !after, "added {i} {j} {k}");
        }
    }

    #[test]
    fn closing_at_the_volumes_face_does_not_erode_the_cut() {
        let n = 12;
        let inside: Vec<bool> = (0..n * n * n).map(|at| at / (n * n) < 6).collect();
        let mut m = Mask {
            dims: [n, n, n],
            inside: inside.clone(),
        };
        m.close(3);
        assert_eq!(m.inside, inside);
    }

    #[test]
    fn the_largest_piece_is_kept_and_the_stray_voxel_dropped() {
        let mut m = hollow_ball(24, 9.0, 2.0, false);
        let before = m.count();
        assert_eq!(m.keep_largest_piece(), 2);
        assert_eq!(m.count(), before - 1);
        assert!(!m.inside[1 + 24 * (1 + 24)]);
    }

    #[test]
    fn an_enclosed_hollow_is_filled_in_3d() {
        let mut m = hollow_ball(24, 9.0, 2.0, false);
        m.keep_largest_piece();
        let added = m.fill_enclosed();
        // The hollow is a ball of radius 7: about 4/3 π 7³ ≈ 1437 voxels.
        assert!((1200..1700).contains(&added), "{added}");
        let c = 12 + 24 * (12 + 24 * 12);
        assert!(m.inside[c]);
    }

    #[test]
    fn a_hollow_open_to_the_edge_by_a_tube_is_filled_only_slice_by_slice() {
        let mut m = hollow_ball(24, 9.0, 2.0, true);
        m.keep_largest_piece();
        assert_eq!(
            m.fill_enclosed(),
            0,
            "open to the bottom face: nothing is enclosed in 3-D"
        );
        let added = m.fill_slices(2);
        assert!(added > 1000, "{added}");
        // The tube below the ball stays open: it is air in its slices too.
        assert!(!m.inside[12 + 24 * (12 + 24)]);
    }
}
