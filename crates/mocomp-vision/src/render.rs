//! A synthetic IR + depth frame renderer with known ground truth: a marker geometry at a pose,
//! rendered as bright blobs with soft edges and depth holes at the fiducials, depth and IR noise,
//! and distractors (sun spots, reflections, a hand passing in front).

use crate::geometry::MarkerGeometry;
use crate::intrinsics::Intrinsics;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Distractors to add.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Distractors {
    /// Large saturated patches (sunlight), bigger than any fiducial.
    pub sun_spots: usize,
    /// Small bright spots the size of fiducials (reflections) on the background.
    pub reflections: usize,
    /// A hand passing close to the camera: moderately bright, nearer than the depth range, and
    /// covering part of the image (it may hide fiducials).
    pub hand: bool,
    /// Seeds where the sun spots and reflections are (`None`: the frame's seed, so they move
    /// from frame to frame; a live camera's stay where they are).
    pub placement_seed: Option<u64>,
}

/// What to render.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderOptions {
    /// Camera.
    pub intrinsics: Intrinsics,
    /// Where the marker is (`tracker_from_marker`, camera frame).
    pub tracker_from_marker: Isometry3<f64>,
    /// Fiducial radius, metres.
    pub fiducial_radius_m: f64,
    /// IR value at a fiducial's centre.
    pub peak_ir: u16,
    /// Mean IR of the scene.
    pub background_ir: f64,
    /// IR noise (standard deviation, counts).
    pub ir_noise: f64,
    /// Width of the soft edge of a fiducial, pixels.
    pub soft_edge_px: f64,
    /// Depth of the wall behind the scene, metres.
    pub background_depth_m: f64,
    /// Radius around each fiducial (metres) where the depth reads the surface it sits on.
    pub surface_radius_m: f64,
    /// How far behind a fiducial's centre that surface is, metres (0: flat fiducials).
    pub surface_offset_m: f64,
    /// Depth noise (standard deviation), metres.
    pub depth_noise_m: f64,
    /// Extra pixels around a fiducial whose depth reads 0.
    pub hole_margin_px: f64,
    /// Fiducials not drawn (0-based).
    pub hidden: Vec<usize>,
    /// Distractors.
    pub distractors: Distractors,
    /// RNG seed.
    pub seed: u64,
}

impl RenderOptions {
    /// Kinect-v2-like defaults for a marker at `pose`: 8 mm fiducial radius, IR noise 400 counts,
    /// 1.5 mm depth noise, a wall at 2.2 m.
    pub fn kinect(tracker_from_marker: Isometry3<f64>, seed: u64) -> Self {
        Self {
            intrinsics: Intrinsics::kinect_v2(),
            tracker_from_marker,
            fiducial_radius_m: 0.008,
            peak_ir: 60_000,
            background_ir: 2_000.0,
            ir_noise: 400.0,
            soft_edge_px: 1.0,
            background_depth_m: 2.2,
            surface_radius_m: 0.03,
            surface_offset_m: 0.0,
            depth_noise_m: 0.0015,
            hole_margin_px: 0.7,
            hidden: Vec::new(),
            distractors: Distractors::default(),
            seed,
        }
    }
}

/// A rendered frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendered {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// IR image.
    pub ir: Vec<u16>,
    /// Depth image, mm (0 = no reading).
    pub depth: Vec<u16>,
    /// Whether each fiducial was drawn inside the image and not covered.
    pub visible: Vec<bool>,
}

fn smoothstep(x: f64) -> f64 {
    let t = x.clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Renders a frame. Deterministic for a given seed.
pub fn render(geometry: &MarkerGeometry, o: &RenderOptions) -> Rendered {
    let k = &o.intrinsics;
    let (w, h) = (k.width as usize, k.height as usize);
    let mut rng = ChaCha8Rng::seed_from_u64(o.seed);
    let mut gauss = move |s: f64| rng.sample::<f64, _>(StandardNormal) * s;
    let mut ir_f = vec![0.0f64; w * h];
    let mut depth_m = vec![o.background_depth_m; w * h];
    for v in ir_f.iter_mut() {
        *v = o.background_ir;
    }
    // Fiducials: project, draw the surface around, then the bright disc and its depth hole.
    let centres: Vec<Vector3<f64>> = geometry
        .points
        .iter()
        .map(|p| (o.tracker_from_marker * p).coords)
        .collect();
    let mut visible = vec![false; centres.len()];
    let mut discs = Vec::new();
    for (i, c) in centres.iter().enumerate() {
        let Some((u, v)) = k.project(c) else { continue };
        let r_px = k.fx * o.fiducial_radius_m / c.z;
        let s_px = k.fx * o.surface_radius_m / c.z;
        let inside = u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64;
        let surface_z = c.z + o.surface_offset_m;
        for_disc(w, h, u, v, s_px, |idx, _| depth_m[idx] = surface_z);
        if o.hidden.contains(&i) {
            continue;
        }
        visible[i] = inside;
        discs.push((u, v, r_px));
    }
    for &(u, v, r_px) in &discs {
        let edge = o.soft_edge_px.max(1e-3);
        for_disc(w, h, u, v, r_px + edge, |idx, d| {
            let a = smoothstep((r_px + 0.5 * edge - d) / edge);
            ir_f[idx] =
                ir_f[idx].max(o.background_ir + a * (f64::from(o.peak_ir) - o.background_ir));
        });
        for_disc(w, h, u, v, r_px + o.hole_margin_px, |idx, _| {
            depth_m[idx] = 0.0
        });
    }
    // Distractors.
    let place = |rng_u: f64, rng_v: f64| (rng_u * w as f64, rng_v * h as f64);
    let mut drng =
        ChaCha8Rng::seed_from_u64(o.distractors.placement_seed.unwrap_or(o.seed) ^ 0x5eed_d15c);
    for _ in 0..o.distractors.sun_spots {
        let (u, v) = place(drng.random(), drng.random());
        let r = 14.0 + 10.0 * drng.random::<f64>();
        for_disc(w, h, u, v, r, |idx, _| ir_f[idx] = 65_535.0);
    }
    for _ in 0..o.distractors.reflections {
        let (u, v) = place(drng.random(), drng.random());
        let r = 2.0 + 2.0 * drng.random::<f64>();
        for_disc(w, h, u, v, r, |idx, d| {
            ir_f[idx] = ir_f[idx].max(50_000.0 * smoothstep(r + 0.5 - d));
        });
    }
    if o.distractors.hand {
        // An ellipse 0.35 m from the camera across the lower left, skin-bright in IR.
        let (cu, cv, ru, rv) = (
            0.3 * w as f64,
            0.7 * h as f64,
            0.22 * w as f64,
            0.18 * h as f64,
        );
        for y in 0..h {
            for x in 0..w {
                let dx = (x as f64 - cu) / ru;
                let dy = (y as f64 - cv) / rv;
                if dx * dx + dy * dy <= 1.0 {
                    let idx = y * w + x;
                    ir_f[idx] = 30_000.0;
                    depth_m[idx] = 0.35;
                }
            }
        }
        for (i, c) in centres.iter().enumerate() {
            if let Some((u, v)) = k.project(c) {
                let dx = (u - cu) / ru;
                let dy = (v - cv) / rv;
                if dx * dx + dy * dy <= 1.0 {
                    visible[i] = false;
                }
            }
        }
    }
    let ir = ir_f
        .iter()
        .map(|v| (v + gauss(o.ir_noise)).round().clamp(0.0, 65_535.0) as u16)
        .collect();
    let depth = depth_m
        .iter()
        .map(|&z| {
            if z <= 0.0 {
                0
            } else {
                ((z + gauss(o.depth_noise_m)) * 1000.0)
                    .round()
                    .clamp(1.0, 65_535.0) as u16
            }
        })
        .collect();
    Rendered {
        width: k.width,
        height: k.height,
        ir,
        depth,
        visible,
    }
}

/// A marker pose in a Kinect's view, for synthetic sequences: 0.7–1.6 m away, within the central
/// part of the field of view, the marker's +x axis (the face of NDI-style planar markers) turned
/// toward the camera within about ±35°, and spun about it at random. Deterministic in `seed`.
pub fn view_pose(seed: u64) -> Isometry3<f64> {
    use mocomp_geom::nalgebra::Translation3;
    use mocomp_geom::quat_from_rotvec;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut u = move || rng.random::<f64>();
    let z = 0.7 + 0.9 * u();
    let x = (u() - 0.5) * 0.5 * z;
    let y = (u() - 0.5) * 0.4 * z;
    let face = quat_from_rotvec(&Vector3::new(0.0, std::f64::consts::FRAC_PI_2, 0.0));
    let tilt = quat_from_rotvec(&Vector3::new(
        (u() - 0.5) * 1.2,
        (u() - 0.5) * 1.2,
        (u() - 0.5) * 6.0,
    ));
    Isometry3::from_parts(Translation3::new(x - 0.02, y - 0.04, z), tilt * face)
}

/// Calls `f(index, distance)` for every pixel whose centre is within `r` of `(u, v)`.
fn for_disc(w: usize, h: usize, u: f64, v: f64, r: f64, mut f: impl FnMut(usize, f64)) {
    if r <= 0.0 {
        return;
    }
    let x0 = (u - r).floor().max(0.0) as usize;
    let y0 = (v - r).floor().max(0.0) as usize;
    let x1 = ((u + r).ceil() as isize).min(w as isize - 1);
    let y1 = ((v + r).ceil() as isize).min(h as isize - 1);
    if x1 < 0 || y1 < 0 {
        return;
    }
    for y in y0..=y1 as usize {
        for x in x0..=x1 as usize {
            let d = ((x as f64 - u).powi(2) + (y as f64 - v).powi(2)).sqrt();
            if d <= r {
                f(y * w + x, d);
            }
        }
    }
}
