//! The patient's MRI in the console: when `[head] mesh` is a T1 in NIfTI, the page shows it as
//! three slices through the target (the image's own voxels, sampled on the image's RAS axes:
//! [`mocomp_mri::slice`]) with the target, the coil, the landmarks and the 10-20 positions drawn
//! on them. `GET /api/mri` says whether there is an image, its extent and window, and where the
//! landmarks, the 10-20 positions and the session's targets are in it (RAS, mm); `GET
//! /api/mri/slice.png` is one slice, windowed. The coil and the goal, live, come in each status
//! ([`crate::state::ImageNow`]).

use mocomp_app::config::Setup;
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_mri::Volume;
use mocomp_mri::slice::{Plane, Sampler, bounds, default_window, grey};
use serde::Serialize;
use std::path::Path;

/// A point in the image, by name.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NamedPoint {
    /// Its name.
    pub name: String,
    /// RAS, mm.
    pub p_mm: [f64; 3],
}

/// A coil pose in the image: its centre and its axis (into the head).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CoilInImage {
    /// The target's name.
    pub name: String,
    /// The coil's centre, RAS, mm.
    pub p_mm: [f64; 3],
    /// Its z axis (into the head), a unit vector.
    pub axis: [f64; 3],
}

/// `GET /api/mri`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MriJson {
    /// Whether the session has an MRI to show.
    pub available: bool,
    /// Why not, when it has none.
    pub why: Option<String>,
    /// The voxel centres' RAS bounding box: [x, y, z] each [least, most], mm.
    pub bounds_mm: [[f64; 2]; 3],
    /// A slice's pixel, mm.
    pub step_mm: f64,
    /// The default window (grey from black to white), intensities.
    pub window: [f32; 2],
    /// The volume's least and greatest intensity.
    pub range: [f32; 2],
    /// The landmarks (`[head.landmarks]`), RAS mm.
    pub landmarks: Vec<NamedPoint>,
    /// The 10-20 positions on the scalp, RAS mm (none when the landmarks do not give them).
    pub eeg: Vec<NamedPoint>,
    /// The session's targets in the image.
    pub targets: Vec<CoilInImage>,
}

/// The MRI the console shows, when there is one.
#[derive(Debug)]
pub struct MriView {
    volume: Option<Volume>,
    /// What the page is told.
    pub json: MriJson,
}

fn mm(p: &Point3<f64>) -> [f64; 3] {
    [p.x * 1e3, p.y * 1e3, p.z * 1e3]
}

fn vec3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// A coil pose as the page draws it.
pub fn coil_in_image(name: &str, image_from_coil: &Isometry3<f64>) -> CoilInImage {
    CoilInImage {
        name: name.to_string(),
        p_mm: mm(&Point3::from(image_from_coil.translation.vector)),
        axis: vec3(&(image_from_coil.rotation * Vector3::z())),
    }
}

impl MriView {
    /// The MRI of `setup` (`[head] mesh` when it is a NIfTI), or why there is none.
    pub fn of(setup: &Setup) -> Self {
        let file = &setup.file;
        let none = |why: String| Self {
            volume: None,
            json: MriJson {
                available: false,
                why: Some(why),
                bounds_mm: [[0.0; 2]; 3],
                step_mm: 1.0,
                window: [0.0, 1.0],
                range: [0.0, 1.0],
                landmarks: Vec::new(),
                eeg: Vec::new(),
                targets: Vec::new(),
            },
        };
        let Some(mesh) = &file.head.mesh else {
            return none("no MRI: [head] mesh is not set (the head is the ellipsoid)".into());
        };
        let path = setup.dir.join(mesh);
        if !is_nifti(&path) {
            return none(format!(
                "no MRI: [head] mesh {} is a surface, not a NIfTI",
                path.display()
            ));
        }
        let unit = file
            .head
            .units
            .as_deref()
            .and_then(|u| mocomp_head::formats::parse_unit(u).ok());
        let volume = match mocomp_app::files::head::read_image(&path, unit) {
            Ok(v) => v,
            Err(e) => return none(format!("no MRI: {e}")),
        };
        let (lo, hi) = bounds(&volume);
        let voxel = volume.voxel_m();
        let step_mm = (voxel.iter().copied().fold(f64::INFINITY, f64::min) * 1e3).max(0.5);
        let window = default_window(&volume);
        let range = volume
            .data
            .iter()
            .fold([f32::INFINITY, f32::NEG_INFINITY], |[a, b], &x| {
                [a.min(x), b.max(x)]
            });
        let image_from_head = file.head.head_from_image.iso().inverse();
        let landmarks = file
            .head
            .landmarks
            .iter()
            .map(|(n, p)| NamedPoint {
                name: n.clone(),
                p_mm: *p,
            })
            .collect();
        let eeg = mocomp_app::navigation::eeg_positions(setup, mocomp_nav::System::TenTwenty)
            .map(|ps| {
                ps.iter()
                    .map(|p| NamedPoint {
                        name: p.name.to_string(),
                        p_mm: mm(&p.point),
                    })
                    .collect()
            })
            .unwrap_or_default();
        let targets = mocomp_app::live::session::SessionSetup::from_setup(setup)
            .map(|s| {
                s.targets
                    .iter()
                    .map(|(name, head_from_coil)| {
                        coil_in_image(name, &(image_from_head * head_from_coil))
                    })
                    .collect()
            })
            .unwrap_or_default();
        Self {
            json: MriJson {
                available: true,
                why: None,
                bounds_mm: std::array::from_fn(|a| [lo[a] * 1e3, hi[a] * 1e3]),
                step_mm,
                window: [window.0, window.1],
                range,
                landmarks,
                eeg,
                targets,
            },
            volume: Some(volume),
        }
    }

    /// The slice in `plane` through `at_mm` (RAS), grey from `window.0` to `window.1`, as PNG.
    pub fn slice_png(
        &self,
        plane: Plane,
        at_mm: [f64; 3],
        window: (f32, f32),
    ) -> Result<Vec<u8>, String> {
        let volume = self.volume.as_ref().ok_or("this session has no MRI")?;
        let sampler = Sampler::new(volume).ok_or("the image's affine is singular")?;
        let at = Point3::new(at_mm[0] * 1e-3, at_mm[1] * 1e-3, at_mm[2] * 1e-3);
        let s = sampler.slice(plane, &at, self.json.step_mm * 1e-3);
        let pixels = grey(&s.values, window.0, window.1);
        let (w, h) = (
            u32::try_from(s.width).map_err(|e| e.to_string())?,
            u32::try_from(s.height).map_err(|e| e.to_string())?,
        );
        let mut png = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut png),
            &pixels,
            w,
            h,
            image::ExtendedColorType::L8,
        )
        .map_err(|e| e.to_string())?;
        Ok(png)
    }
}

fn is_nifti(p: &Path) -> bool {
    mocomp_app::files::head::nifti_extension(p).is_some()
}
