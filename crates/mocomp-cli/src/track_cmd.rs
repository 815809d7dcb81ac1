//! `mocomp track` and `mocomp track render`: frames from and to directories of 16-bit PNG pairs.
//!
//! A frames directory holds `<name>_ir.png` and `<name>_depth.png` (16-bit grayscale; depth in
//! mm, 0 = no reading) for each frame; `render` also writes `intrinsics.toml` and `truth.jsonl`.

use anyhow::{Context, Result};
use mocomp_geom::matrix_mm_from_iso;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::units::m_to_mm;
use mocomp_vision::codec::{decode_gray16_png, encode_gray16_png, encode_rgb_png};
use mocomp_vision::overlay::overlay;
use mocomp_vision::render::{Distractors, RenderOptions, render, view_pose};
use mocomp_vision::{Frame, Intrinsics, MarkerGeometry, TrackParams, Tracker};
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Reads a marker geometry file (.toml, .ini, .rom).
pub fn read_geometry(path: &Path) -> Result<MarkerGeometry> {
    let bytes = std::fs::read(path)
        .with_context(|| format!("--geometry {}: cannot read", path.display()))?;
    Ok(MarkerGeometry::from_file_bytes(
        &bytes,
        &path.display().to_string(),
    )?)
}

/// Reads an intrinsics TOML file.
pub fn read_intrinsics(path: &Path) -> Result<Intrinsics> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("--intrinsics {name}: cannot read"))?;
    Ok(Intrinsics::from_toml_str(&text, &name)?)
}

fn rows_mm(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = matrix_mm_from_iso(t);
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// The frames in a directory: `(name, ir path, depth path)`, sorted by name.
fn list_frames(dir: &Path) -> Result<Vec<(String, PathBuf, PathBuf)>> {
    let entries = std::fs::read_dir(dir)
        .with_context(|| format!("--frames {}: cannot read the directory", dir.display()))?;
    let mut frames = Vec::new();
    for e in entries {
        let path = e?.path();
        let Some(file) = path.file_name().and_then(|f| f.to_str()) else {
            continue;
        };
        if let Some(name) = file.strip_suffix("_ir.png") {
            let depth = dir.join(format!("{name}_depth.png"));
            if !depth.exists() {
                return Err(crate::UsageError(format!(
                    "{}: no matching depth image {}",
                    path.display(),
                    depth.display()
                ))
                .into());
            }
            frames.push((name.to_string(), path.clone(), depth));
        }
    }
    if frames.is_empty() {
        return Err(crate::UsageError(format!(
            "--frames {}: no <name>_ir.png / <name>_depth.png pairs",
            dir.display()
        ))
        .into());
    }
    frames.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(frames)
}

#[derive(Serialize)]
struct FrameJson<'a> {
    frame: &'a str,
    found: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    tracker_from_marker: Option<[[f64; 4]; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    fre_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    blobs: usize,
}

/// Options of `mocomp track`.
#[derive(Debug)]
pub struct TrackArgs<'a> {
    /// Frames directory.
    pub frames: &'a Path,
    /// Intrinsics file.
    pub intrinsics: &'a Path,
    /// Geometry file.
    pub geometry: &'a Path,
    /// Parameters file (TOML), optional.
    pub params: Option<&'a Path>,
    /// Where to write overlays.
    pub overlay: Option<&'a Path>,
    /// JSON lines.
    pub json: bool,
}

/// `mocomp track`.
pub fn track(out: &mut impl Write, a: &TrackArgs<'_>) -> Result<()> {
    let intrinsics = read_intrinsics(a.intrinsics)?;
    let geometry = read_geometry(a.geometry)?;
    let params = match a.params {
        Some(p) => {
            let name = p.display().to_string();
            let text = std::fs::read_to_string(p)
                .with_context(|| format!("--params {name}: cannot read"))?;
            TrackParams::from_toml_str(&text, &name)?
        }
        None => TrackParams::default(),
    };
    let report = geometry.analyze(mocomp_geom::units::mm_to_m(params.match_tolerance_mm));
    for w in &report.warnings {
        eprintln!("warning: {}: {w}", a.geometry.display());
    }
    let mut tracker = Tracker::new(intrinsics, params, geometry)?;
    if let Some(dir) = a.overlay {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("--overlay {}: cannot create", dir.display()))?;
    }
    let frames = list_frames(a.frames)?;
    let mut found = 0usize;
    for (name, ir_path, depth_path) in &frames {
        let read = |p: &Path| -> Result<mocomp_vision::codec::Gray16> {
            let bytes =
                std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?;
            Ok(decode_gray16_png(&bytes, &p.display().to_string())?)
        };
        let ir = read(ir_path)?;
        let depth = read(depth_path)?;
        if (ir.width, ir.height) != (depth.width, depth.height) {
            return Err(mocomp_vision::VisionError::SizeMismatch {
                what: depth_path.display().to_string(),
                got_w: depth.width,
                got_h: depth.height,
                want_w: ir.width,
                want_h: ir.height,
            }
            .into());
        }
        let frame = Frame::new(ir.width, ir.height, &ir.data, &depth.data)?;
        let result = tracker
            .process(&frame)
            .map_err(|e| crate::UsageError(format!("{}: {e}", ir_path.display())))?;
        if let Some(dir) = a.overlay {
            let img = overlay(&frame, tracker.scan_area(), &result);
            let path = dir.join(format!("{name}_overlay.png"));
            std::fs::write(
                &path,
                encode_rgb_png(img.width, img.height, &img.data, name)?,
            )
            .with_context(|| format!("{}: cannot write", path.display()))?;
        }
        found += usize::from(result.detection.is_some());
        if a.json {
            let j = FrameJson {
                frame: name,
                found: result.detection.is_some(),
                tracker_from_marker: result
                    .detection
                    .as_ref()
                    .map(|d| rows_mm(&d.tracker_from_marker)),
                fre_mm: result.detection.as_ref().map(|d| m_to_mm(d.fre_m)),
                reason: result.not_found.as_ref().map(|r| r.to_string()),
                blobs: result.blobs.len(),
            };
            writeln!(out, "{}", serde_json::to_string(&j)?)?;
        } else {
            match (&result.detection, &result.not_found) {
                (Some(d), _) => {
                    let t = d.tracker_from_marker.translation.vector;
                    writeln!(
                        out,
                        "{name}: found at ({:.1}, {:.1}, {:.1}) mm, FRE {:.2} mm, {} blobs",
                        m_to_mm(t.x),
                        m_to_mm(t.y),
                        m_to_mm(t.z),
                        m_to_mm(d.fre_m),
                        result.blobs.len()
                    )?;
                }
                (None, Some(r)) => {
                    writeln!(out, "{name}: not found: {r} ({} blobs)", result.blobs.len())?
                }
                (None, None) => writeln!(out, "{name}: not found")?,
            }
        }
    }
    if !a.json {
        writeln!(
            out,
            "found the marker in {found} of {} frames",
            frames.len()
        )?;
    }
    Ok(())
}

/// Options of `mocomp track render`.
#[derive(Debug)]
pub struct RenderArgs<'a> {
    /// Output directory.
    pub out_dir: &'a Path,
    /// Geometry file.
    pub geometry: &'a Path,
    /// Intrinsics file (default: typical Kinect v2).
    pub intrinsics: Option<&'a Path>,
    /// Frames.
    pub count: usize,
    /// Seed.
    pub seed: u64,
    /// Add sun spots, reflections and a hand.
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

/// `mocomp track render`.
pub fn render_frames(out: &mut impl Write, a: &RenderArgs<'_>) -> Result<()> {
    let geometry = read_geometry(a.geometry)?;
    let intrinsics = match a.intrinsics {
        Some(p) => read_intrinsics(p)?,
        None => Intrinsics::kinect_v2(),
    };
    if let Some(h) = a.hide
        && (h == 0 || h > geometry.len())
    {
        return Err(crate::UsageError(format!(
            "--hide {h}: the geometry has fiducials 1..{}",
            geometry.len()
        ))
        .into());
    }
    std::fs::create_dir_all(a.out_dir)
        .with_context(|| format!("--out {}: cannot create", a.out_dir.display()))?;
    let mut truth = String::new();
    for i in 0..a.count {
        let name = format!("{i:04}");
        let pose = view_pose(a.seed.wrapping_mul(1_000_003).wrapping_add(i as u64));
        let mut o =
            RenderOptions::kinect(pose, a.seed.wrapping_mul(1_000_003).wrapping_add(i as u64));
        o.intrinsics = intrinsics;
        if a.distractors {
            o.distractors = Distractors {
                sun_spots: 1,
                reflections: 4,
                hand: i % 5 == 4,
            };
        }
        if let Some(h) = a.hide {
            o.hidden = vec![h - 1];
        }
        let img = render(&geometry, &o);
        for (suffix, data) in [("ir", &img.ir), ("depth", &img.depth)] {
            let path = a.out_dir.join(format!("{name}_{suffix}.png"));
            std::fs::write(
                &path,
                encode_gray16_png(img.width, img.height, data, &name)?,
            )
            .with_context(|| format!("{}: cannot write", path.display()))?;
        }
        truth.push_str(&serde_json::to_string(&TruthJson {
            frame: &name,
            tracker_from_marker: rows_mm(&pose),
            visible: img.visible,
        })?);
        truth.push('\n');
    }
    std::fs::write(a.out_dir.join("truth.jsonl"), truth)?;
    let k = &intrinsics;
    let centre = match k.pixel_centre {
        mocomp_vision::intrinsics::PixelCentre::Integer => "integer",
        mocomp_vision::intrinsics::PixelCentre::Half => "half",
    };
    std::fs::write(
        a.out_dir.join("intrinsics.toml"),
        format!(
            "width = {}\nheight = {}\nfx = {:?}\nfy = {:?}\ncx = {:?}\ncy = {:?}\nk1 = {:?}\nk2 = {:?}\nk3 = {:?}\np1 = {:?}\np2 = {:?}\npixel_centre = \"{centre}\"\n",
            k.width, k.height, k.fx, k.fy, k.cx, k.cy, k.k1, k.k2, k.k3, k.p1, k.p2
        ),
    )?;
    writeln!(
        out,
        "wrote {} frames ({}×{}) with truth.jsonl and intrinsics.toml to {}",
        a.count,
        k.width,
        k.height,
        a.out_dir.display()
    )?;
    Ok(())
}
