//! The surface drawn from three sides, to see at a glance that what was read is a head and
//! which way it faces: orthographic views along the file's axes (in RAS: from the front, from
//! the left, from above), shaded by the surface's slope to the eye, side by side.

use crate::mesh::Mesh;
use mocomp_geom::nalgebra::{Point3, Vector3};

/// An RGB picture, rows top to bottom.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Red, green, blue per pixel.
    pub rgb: Vec<u8>,
}

/// A view: its name, the direction to the eye, the picture's right and up (unit vectors).
pub type View = (&'static str, [f64; 3], [f64; 3], [f64; 3]);

/// The three views.
pub const VIEWS: [View; 3] = [
    // Seen as one sees a person facing one: their left (-x in RAS) on the picture's right.
    (
        "front (from +y)",
        [0.0, 1.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0],
    ),
    (
        "left (from -x)",
        [-1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
    ),
    (
        "top (from +z)",
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
    ),
];

/// `mesh` drawn in the three [`VIEWS`], each `size` pixels square (at least 16).
pub fn three_views(mesh: &Mesh, size: u32) -> Picture {
    let size = size.max(16);
    let (w, h) = (size * 3, size);
    let mut rgb = vec![255u8; (w * h * 3) as usize];
    let Some(b) = mesh.bounds() else {
        return Picture {
            width: w,
            height: h,
            rgb,
        };
    };
    let centre = Point3::from((b.min.coords + b.max.coords) / 2.0);
    // One scale for all three views: the largest extent fills 90 % of a panel.
    let scale = 0.9 * f64::from(size) / b.extent().max(1e-12);
    for (panel, (_, eye, right, up)) in VIEWS.iter().enumerate() {
        let (eye, right, up) = (
            Vector3::from(*eye),
            Vector3::from(*right),
            Vector3::from(*up),
        );
        let mut depth = vec![f64::NEG_INFINITY; (size * size) as usize];
        let project = |p: &Point3<f64>| {
            let d = p - centre;
            (
                f64::from(size) / 2.0 + d.dot(&right) * scale,
                f64::from(size) / 2.0 - d.dot(&up) * scale,
                d.dot(&eye),
            )
        };
        for t in &mesh.triangles {
            let [a, bb, c] = t.map(|i| mesh.vertices[i as usize]);
            let n = (bb - a).cross(&(c - a));
            let Some(n) = n.try_normalize(1e-30) else {
                continue;
            };
            // Lit from the eye: the surface facing it is bright, its edges dark.
            let shade = n.dot(&eye).abs();
            let grey = (60.0 + 180.0 * shade) as u8;
            let [pa, pb, pc] = [project(&a), project(&bb), project(&c)];
            fill(
                &mut rgb,
                &mut depth,
                w,
                size,
                panel as u32,
                [pa, pb, pc],
                grey,
            );
        }
    }
    Picture {
        width: w,
        height: h,
        rgb,
    }
}

/// Fills a projected triangle into `panel`, keeping the nearest surface (largest depth).
fn fill(
    rgb: &mut [u8],
    depth: &mut [f64],
    width: u32,
    size: u32,
    panel: u32,
    p: [(f64, f64, f64); 3],
    grey: u8,
) {
    let xs = [p[0].0, p[1].0, p[2].0];
    let ys = [p[0].1, p[1].1, p[2].1];
    let clamp = |v: f64| v.clamp(0.0, f64::from(size - 1));
    let (x0, x1) = (
        clamp(xs.iter().copied().fold(f64::INFINITY, f64::min).floor()),
        clamp(xs.iter().copied().fold(f64::NEG_INFINITY, f64::max).ceil()),
    );
    let (y0, y1) = (
        clamp(ys.iter().copied().fold(f64::INFINITY, f64::min).floor()),
        clamp(ys.iter().copied().fold(f64::NEG_INFINITY, f64::max).ceil()),
    );
    let area = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
    if area.abs() < 1e-12 {
        return;
    }
    for y in (y0 as u32)..=(y1 as u32) {
        for x in (x0 as u32)..=(x1 as u32) {
            let (px, py) = (f64::from(x) + 0.5, f64::from(y) + 0.5);
            let w0 = ((p[1].0 - px) * (p[2].1 - py) - (p[2].0 - px) * (p[1].1 - py)) / area;
            let w1 = ((p[2].0 - px) * (p[0].1 - py) - (p[0].0 - px) * (p[2].1 - py)) / area;
            let w2 = 1.0 - w0 - w1;
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let z = w0 * p[0].2 + w1 * p[1].2 + w2 * p[2].2;
            let k = (y * size + x) as usize;
            if z > depth[k] {
                depth[k] = z;
                let o = ((y * width + panel * size + x) * 3) as usize;
                rgb[o..o + 3].copy_from_slice(&[grey, grey, grey.saturating_add(12)]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::tests::ellipsoid_mesh;

    /// An ellipsoid taller than wide fills a taller-than-wide patch in the front view and a
    /// round-ish one from the top, centred, on white.
    #[test]
    fn the_views_show_the_shape() {
        let m = ellipsoid_mesh(&Vector3::new(0.05, 0.08, 0.1), 3);
        let pic = three_views(&m, 100);
        assert_eq!((pic.width, pic.height, pic.rgb.len()), (300, 100, 90_000));
        let drawn = |panel: u32, x: u32, y: u32| {
            let o = ((y * 300 + panel * 100 + x) * 3) as usize;
            pic.rgb[o] != 255
        };
        let extent = |panel: u32| {
            let cols = (0..100)
                .filter(|&x| (0..100).any(|y| drawn(panel, x, y)))
                .count();
            let rows = (0..100)
                .filter(|&y| (0..100).any(|x| drawn(panel, x, y)))
                .count();
            (cols, rows)
        };
        // Scale: 0.2 m (the height) is 90 px.
        let (c, r) = extent(0);
        assert!(
            (c as i64 - 45).abs() <= 2 && (r as i64 - 90).abs() <= 2,
            "{c} {r}"
        );
        let (c, r) = extent(1);
        assert!(
            (c as i64 - 72).abs() <= 2 && (r as i64 - 90).abs() <= 2,
            "{c} {r}"
        );
        let (c, r) = extent(2);
        assert!(
            (c as i64 - 45).abs() <= 2 && (r as i64 - 72).abs() <= 2,
            "{c} {r}"
        );
        assert!(drawn(0, 50, 50) && !drawn(0, 2, 2));
    }
}
