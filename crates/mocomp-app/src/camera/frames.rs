//! IR + depth frames from and to directories of 16-bit PNG pairs (`mocomp track`, `mocomp track
//! render`): the files around `mocomp-vision`'s pipeline, which works on buffers.
//!
//! A frames directory holds `<name>_ir.png` and `<name>_depth.png` (16-bit grayscale; depth in
//! mm, 0 = no reading) for each frame; a rendered one also `intrinsics.toml` and `truth.jsonl`.

use crate::{AppError, Context};
use mocomp_geom::matrix_mm_from_iso;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::units::m_to_mm;
use mocomp_vision::codec::{Gray16, decode_gray16_png, encode_gray16_png, encode_rgb_png};
use mocomp_vision::overlay::overlay;
use mocomp_vision::render::{Distractors, RenderOptions, render, view_pose};
use mocomp_vision::{Frame, FrameResult, Intrinsics, MarkerGeometry, TrackParams, Tracker};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Reads a marker geometry file (.toml, .ini, .rom).
pub fn read_geometry(path: &Path) -> Result<MarkerGeometry, AppError> {
    let bytes =
        std::fs::read(path).what(|| format!("--geometry {}: cannot read", path.display()))?;
    MarkerGeometry::from_file_bytes(&bytes, &path.display().to_string())
        .what(|| "--geometry".to_string())
}

/// Reads an intrinsics TOML file.
pub fn read_intrinsics(path: &Path) -> Result<Intrinsics, AppError> {
    let name = path.display().to_string();
    let text =
        std::fs::read_to_string(path).what(|| format!("--intrinsics {name}: cannot read"))?;
    Intrinsics::from_toml_str(&text, &name).what(|| "--intrinsics".to_string())
}

/// Reads a pipeline parameters TOML file.
pub fn read_params(path: &Path) -> Result<TrackParams, AppError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).what(|| format!("--params {name}: cannot read"))?;
    TrackParams::from_toml_str(&text, &name).what(|| "--params".to_string())
}

/// The frames in a directory: `(name, ir path, depth path)`, sorted by name.
pub fn list(dir: &Path) -> Result<Vec<(String, PathBuf, PathBuf)>, AppError> {
    let what = || format!("--frames {}: cannot read the directory", dir.display());
    let mut frames = Vec::new();
    for e in std::fs::read_dir(dir).what(what)? {
        let path = e.what(what)?.path();
        let Some(file) = path.file_name().and_then(|f| f.to_str()) else {
            continue;
        };
        if let Some(name) = file.strip_suffix("_ir.png") {
            let depth = dir.join(format!("{name}_depth.png"));
            if !depth.exists() {
                return Err(AppError::Config(format!(
                    "{}: no matching depth image {}",
                    path.display(),
                    depth.display()
                )));
            }
            frames.push((name.to_string(), path.clone(), depth));
        }
    }
    if frames.is_empty() {
        return Err(AppError::Config(format!(
            "--frames {}: no <name>_ir.png / <name>_depth.png pairs",
            dir.display()
        )));
    }
    frames.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(frames)
}

fn read_png(p: &Path) -> Result<Gray16, AppError> {
    let bytes = std::fs::read(p).what(|| format!("{}: cannot read", p.display()))?;
    decode_gray16_png(&bytes, &p.display().to_string()).what(|| p.display().to_string())
}

/// Runs `tracker` over every frame of `dir` in name order, writing an overlay per frame into
/// `overlay_dir` when given; `each` is told each frame's name and result.
pub fn track_dir(
    dir: &Path,
    tracker: &mut Tracker,
    overlay_dir: Option<&Path>,
    each: &mut dyn FnMut(&str, &FrameResult) -> Result<(), AppError>,
) -> Result<usize, AppError> {
    if let Some(d) = overlay_dir {
        std::fs::create_dir_all(d).what(|| format!("--overlay {}: cannot create", d.display()))?;
    }
    let frames = list(dir)?;
    for (name, ir_path, depth_path) in &frames {
        let ir = read_png(ir_path)?;
        let depth = read_png(depth_path)?;
        if (ir.width, ir.height) != (depth.width, depth.height) {
            return Err(AppError::failed(
                depth_path.display().to_string(),
                mocomp_vision::VisionError::SizeMismatch {
                    what: depth_path.display().to_string(),
                    got_w: depth.width,
                    got_h: depth.height,
                    want_w: ir.width,
                    want_h: ir.height,
                },
            ));
        }
        let frame = Frame::new(ir.width, ir.height, &ir.data, &depth.data)
            .what(|| ir_path.display().to_string())?;
        let result = track_frame(name, &frame, tracker, overlay_dir)
            .map_err(|e| AppError::failed(ir_path.display().to_string(), e))?;
        each(name, &result)?;
    }
    Ok(frames.len())
}

/// Tracks one frame named `name`, writing its overlay (`<name>_overlay.png`) into
/// `overlay_dir` when given: the step every frame source shares.
pub fn track_frame(
    name: &str,
    frame: &Frame<'_>,
    tracker: &mut Tracker,
    overlay_dir: Option<&Path>,
) -> Result<FrameResult, AppError> {
    let result = tracker.process(frame).what(|| name.to_string())?;
    if let Some(d) = overlay_dir {
        let img = overlay(frame, tracker.scan_area(), &result);
        let path = d.join(format!("{name}_overlay.png"));
        let png = encode_rgb_png(img.width, img.height, &img.data, name)
            .what(|| format!("{}: cannot encode", path.display()))?;
        std::fs::write(&path, png).what(|| format!("{}: cannot write", path.display()))?;
    }
    Ok(result)
}

/// One frame's result as a line of `mocomp track`'s output: JSON (`json`) or text. The JSON
/// has `frame`, `device_usec` (a recording's capture), `found`, `tracker_from_marker` (4×4, mm),
/// `fre_mm`, `reason` (why not found) and `blobs`.
pub fn frame_line(
    name: &str,
    device_usec: Option<u64>,
    result: &FrameResult,
    json: bool,
) -> String {
    let blobs = result.blobs.len();
    if json {
        #[derive(Serialize)]
        struct Line<'a> {
            frame: &'a str,
            #[serde(skip_serializing_if = "Option::is_none")]
            device_usec: Option<u64>,
            found: bool,
            #[serde(skip_serializing_if = "Option::is_none")]
            tracker_from_marker: Option<[[f64; 4]; 4]>,
            #[serde(skip_serializing_if = "Option::is_none")]
            fre_mm: Option<f64>,
            #[serde(skip_serializing_if = "Option::is_none")]
            reason: Option<String>,
            blobs: usize,
        }
        let d = result.detection.as_ref();
        let line = Line {
            frame: name,
            device_usec,
            found: d.is_some(),
            tracker_from_marker: d.map(|d| rows_mm(&d.tracker_from_marker)),
            fre_mm: d.map(|d| m_to_mm(d.fre_m)),
            reason: result.not_found.as_ref().map(|r| r.to_string()),
            blobs,
        };
        // Numbers and strings always serialise.
        return serde_json::to_string(&line).unwrap_or_default();
    }
    match (&result.detection, &result.not_found) {
        (Some(d), _) => {
            let t = d.tracker_from_marker.translation.vector.map(m_to_mm);
            format!(
                "{name}: found at ({:.1}, {:.1}, {:.1}) mm, FRE {:.2} mm, {blobs} blobs",
                t.x,
                t.y,
                t.z,
                m_to_mm(d.fre_m)
            )
        }
        (None, Some(r)) => format!("{name}: not found: {r} ({blobs} blobs)"),
        (None, None) => format!("{name}: not found"),
    }
}

/// A transform as the rows of a 4×4 matrix with translation in mm (the JSON files' form).
pub fn rows_mm(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = matrix_mm_from_iso(t);
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// What `mocomp track render` writes.
#[derive(Debug, Clone)]
pub struct RenderOptionsDir {
    /// Frames.
    pub count: usize,
    /// Seed.
    pub seed: u64,
    /// Add sun spots, reflections and (every fifth frame) a hand.
    pub distractors: bool,
    /// Hide this fiducial (1-based) in every frame.
    pub hide: Option<usize>,
}

#[derive(Serialize)]
struct TruthJson<'a> {
    frame: &'a str,
    tracker_from_marker: [[f64; 4]; 4],
    visible: Vec<bool>,
}

/// Writes synthetic frames of `geometry` seen by a camera with `intrinsics` into `dir`, with
/// `truth.jsonl` (the true pose and visible fiducials of each) and `intrinsics.toml`; and the same
/// frames into `recording` when given.
pub fn render_dir(
    dir: &Path,
    geometry: &MarkerGeometry,
    intrinsics: &Intrinsics,
    o: &RenderOptionsDir,
    mut recording: Option<&mut crate::camera::k4a_writer::RecordingSink>,
) -> Result<(), AppError> {
    if let Some(h) = o.hide
        && (h == 0 || h > geometry.len())
    {
        return Err(AppError::Config(format!(
            "--hide {h}: the geometry has fiducials 1..{}",
            geometry.len()
        )));
    }
    std::fs::create_dir_all(dir).what(|| format!("--out {}: cannot create", dir.display()))?;
    let mut truth = String::new();
    for i in 0..o.count {
        let name = format!("{i:04}");
        let seed = o.seed.wrapping_mul(1_000_003).wrapping_add(i as u64);
        let pose = view_pose(seed);
        let mut r = RenderOptions::kinect(pose, seed);
        r.intrinsics = *intrinsics;
        if o.distractors {
            r.distractors = Distractors {
                sun_spots: 1,
                reflections: 4,
                hand: i % 5 == 4,
                placement_seed: None,
            };
        }
        if let Some(h) = o.hide {
            r.hidden = vec![h - 1];
        }
        let img = render(geometry, &r);
        if let Some(rec) = recording.as_mut() {
            rec.write(&img.ir, &img.depth)?;
        }
        for (suffix, data) in [("ir", &img.ir), ("depth", &img.depth)] {
            let path = dir.join(format!("{name}_{suffix}.png"));
            let png = encode_gray16_png(img.width, img.height, data, &name)
                .what(|| format!("{}: cannot encode", path.display()))?;
            std::fs::write(&path, png).what(|| format!("{}: cannot write", path.display()))?;
        }
        let line = serde_json::to_string(&TruthJson {
            frame: &name,
            tracker_from_marker: rows_mm(&pose),
            visible: img.visible,
        })
        .what(|| "truth.jsonl")?;
        truth.push_str(&line);
        truth.push('\n');
    }
    let put = |file: &str, text: String| {
        let path = dir.join(file);
        std::fs::write(&path, text).what(|| format!("{}: cannot write", path.display()))
    };
    put("truth.jsonl", truth)?;
    // Every coefficient, the rational ones included, as `Intrinsics` reads it back.
    let text =
        toml::to_string(intrinsics).map_err(|e| AppError::Config(format!("intrinsics: {e}")))?;
    put("intrinsics.toml", text)
}
