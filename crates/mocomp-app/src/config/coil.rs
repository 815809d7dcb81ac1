//! `[coil]`: the coil's solid for the clearance (a cylinder, or SimNIBS's `.stl` casing read
//! into a [`Casing`]) and its field model (the `.ccd` file, the stimulator's dI/dt and the
//! default target depth), checked and read into a [`DoseModel`].

use crate::AppError;
use crate::config::range::Check;
use crate::files::capped::read_capped_text;
use mocomp_efield::{DipoleCoil, DoseModel, parse_ccd};
use mocomp_geom::LengthUnit;
use mocomp_head::casing::Casing;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// `[coil]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CoilSection {
    /// Radius seen from the head, m (the cylinder, where no `casing` is given).
    pub radius_m: f64,
    /// Thickness behind the face, m (the cylinder, where no `casing` is given).
    pub thickness_m: f64,
    /// The coil's casing: a surface (`.stl`, `.obj`, `.ply`) in the coil's frame, millimetres,
    /// as SimNIBS draws them (+z into the head, the origin under the centre of the coil's
    /// bottom; relative to the configuration's directory, absolute once read). With it, every
    /// clearance measures the casing (its convex hull) in place of the cylinder.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub casing: Option<PathBuf>,
    /// The casing as read ([`resolve`]); not part of the file.
    #[serde(skip)]
    pub loaded_casing: Option<Arc<Casing>>,
    /// The coil's field model: a SimNIBS `.ccd` file of magnetic dipoles in the coil's frame
    /// (relative to the configuration's directory; absolute once read). With it, the dose.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model: Option<PathBuf>,
    /// The stimulator's dI/dt, A/µs (or `output_pct` of the model's `dIdtmax`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub didt_a_per_us: Option<f64>,
    /// The stimulator's output, % of the model's `dIdtmax` (its full output).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output_pct: Option<f64>,
    /// A target given as a coil pose alone: the dose is taken this far under the scalp on the
    /// coil's axis, m.
    pub target_depth_m: f64,
}

impl Default for CoilSection {
    fn default() -> Self {
        Self {
            radius_m: 0.04,
            thickness_m: 0.03,
            casing: None,
            loaded_casing: None,
            model: None,
            didt_a_per_us: None,
            output_pct: None,
            target_depth_m: 0.015,
        }
    }
}

/// The largest coil file read, bytes (SimNIBS's largest `.ccd` models are a few megabytes).
pub const MAX_COIL_BYTES: u64 = 64 << 20;

/// The keys' values, each in its range; dI/dt given one way at most, and only with a model.
pub fn check(c: &CoilSection) -> Result<(), AppError> {
    if let Some(d) = c.didt_a_per_us {
        // The largest clinical stimulators reach ~300 A/µs.
        Check::range("coil.didt_a_per_us", d, 0.0, 1000.0, true)?;
    }
    if let Some(p) = c.output_pct {
        Check::range("coil.output_pct", p, 0.0, 100.0, true)?;
    }
    if c.didt_a_per_us.is_some() && c.output_pct.is_some() {
        return Err(AppError::Config(
            "coil.didt_a_per_us and coil.output_pct: give the stimulator's dI/dt one way".into(),
        ));
    }
    if c.model.is_none() && (c.didt_a_per_us.is_some() || c.output_pct.is_some()) {
        return Err(AppError::Config(
            "coil.didt_a_per_us / coil.output_pct: no coil.model to drive (a SimNIBS .ccd file)"
                .into(),
        ));
    }
    // Cortex lies 10–25 mm under the scalp; a target deeper than 50 mm is no cortical one.
    Check::range("coil.target_depth_m", c.target_depth_m, 0.0, 0.05, true)
}

/// The largest casing file read, bytes (SimNIBS's casings are a few hundred kilobytes).
pub const MAX_CASING_BYTES: u64 = 64 << 20;

/// `model`'s and `casing`'s paths relative to `dir`, made absolute (the files must exist), and
/// the casing read (once).
pub fn resolve(c: &mut CoilSection, dir: &Path) -> Result<(), AppError> {
    let absolute = |key: &str, file: &Path| {
        let path = dir.join(file);
        std::fs::canonicalize(&path)
            .map_err(|e| AppError::Config(format!("coil.{key} = {}: {e}", path.display())))
    };
    if let Some(model) = &c.model {
        c.model = Some(absolute("model", model)?);
    }
    if let Some(casing) = &c.casing {
        let path = absolute("casing", casing)?;
        if c.loaded_casing.is_none() {
            let read = read_casing(&path)
                .map_err(|e| AppError::Config(format!("coil.casing = {}: {e}", path.display())))?;
            c.loaded_casing = Some(Arc::new(read));
        }
        c.casing = Some(path);
    }
    Ok(())
}

/// The casing in `path`: its surface's points, millimetres, as the solid (their convex hull).
pub fn read_casing(path: &Path) -> Result<Casing, AppError> {
    let bytes = crate::files::capped::read_capped(path, MAX_CASING_BYTES, "a casing file")?;
    mocomp_head::formats::read_casing(&path.display().to_string(), &bytes, LengthUnit::Millimetre)
        .map_err(|e| AppError::Config(e.to_string()))
}

/// The coil model in `path`.
pub fn read_coil(path: &Path) -> Result<DipoleCoil, AppError> {
    let text = read_capped_text(path, MAX_COIL_BYTES, "a coil file")?;
    parse_ccd(&path.display().to_string(), &text).map_err(|e| AppError::Config(e.to_string()))
}

impl CoilSection {
    /// The field model, read (`None` without `model`). The dI/dt: `didt_a_per_us`, or
    /// `output_pct` (default 100) of the file's `dIdtmax`; a file without `dIdtmax` needs
    /// `didt_a_per_us`.
    pub fn dose_model(&self) -> Result<Option<DoseModel>, AppError> {
        let c = self;
        let Some(path) = &c.model else {
            return Ok(None);
        };
        let coil = read_coil(path).map_err(|e| AppError::Config(format!("coil.model: {e}")))?;
        let didt_a_per_s = match (c.didt_a_per_us, coil.didt_max_a_per_s) {
            (Some(d), _) => d * 1e6,
            (None, Some(max)) => max * c.output_pct.unwrap_or(100.0) / 100.0,
            (None, None) => {
                return Err(AppError::Config(format!(
                    "coil.model = {}: no dIdtmax in its header: give coil.didt_a_per_us",
                    path.display()
                )));
            }
        };
        Ok(Some(DoseModel {
            coil: Arc::new(coil),
            didt_a_per_s,
            depth_m: c.target_depth_m,
        }))
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    fn coils() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../mocomp-efield/tests/data/coils")
    }

    #[test]
    fn a_coil_model_reads_with_its_stimulator_and_bad_keys_are_named() {
        let dir = coils();
        let mut c = CoilSection {
            model: Some("MagStim_D70.ccd".into()),
            output_pct: Some(60.0),
            ..CoilSection::default()
        };
        check(&c).unwrap();
        resolve(&mut c, &dir).unwrap();
        assert!(c.model.as_ref().unwrap().is_absolute());
        let m = c.dose_model().unwrap().unwrap();
        assert_eq!(m.coil.len(), 964);
        assert!((m.didt_a_per_s - 0.6 * 114.73e6).abs() < 1.0);
        // The legacy coil has no dIdtmax.
        c.model = Some(dir.join("Magstim_70mm_Fig8.ccd"));
        c.output_pct = None;
        let e = c.dose_model().unwrap_err().to_string();
        assert!(e.contains("give coil.didt_a_per_us"), "{e}");
        c.didt_a_per_us = Some(80.0);
        assert!((c.dose_model().unwrap().unwrap().didt_a_per_s - 80e6).abs() < 1e-3);
        for (edit, key) in [
            (
                &(|c: &mut CoilSection| c.output_pct = Some(120.0)) as &dyn Fn(&mut CoilSection),
                "coil.output_pct",
            ),
            (
                &|c: &mut CoilSection| c.didt_a_per_us = Some(-1.0),
                "coil.didt_a_per_us",
            ),
            (
                &|c: &mut CoilSection| c.target_depth_m = 0.2,
                "coil.target_depth_m",
            ),
            (&|c: &mut CoilSection| c.output_pct = Some(50.0), "one way"),
        ] {
            let mut bad = c.clone();
            edit(&mut bad);
            let e = check(&bad).unwrap_err().to_string();
            assert!(e.contains(key), "{key}: {e}");
        }
        let mut none = CoilSection {
            model: Some("no-such.ccd".into()),
            ..CoilSection::default()
        };
        let e = resolve(&mut none, &dir).unwrap_err().to_string();
        assert!(e.contains("coil.model") && e.contains("no-such.ccd"), "{e}");
    }

    #[test]
    fn a_casing_is_found_beside_the_configuration_read_once_and_a_bad_one_named() {
        let dir = coils();
        let mut c = CoilSection {
            casing: Some("MagStim_D70.stl".into()),
            ..CoilSection::default()
        };
        resolve(&mut c, &dir).unwrap();
        assert!(c.casing.as_ref().unwrap().is_absolute());
        let casing = Arc::clone(c.loaded_casing.as_ref().unwrap());
        // SimNIBS's frame: the casing ends 1 mm behind the coil's origin, and reaches 100 mm
        // along the wings.
        let (z_min, z_max) = casing.z_span();
        assert!(
            (z_max + 0.001).abs() < 1e-6 && (z_min + 0.019).abs() < 1e-6,
            "{z_min} {z_max}"
        );
        assert!((casing.extent() - 0.1).abs() < 0.01, "{}", casing.extent());
        // Read once: a second resolve (the path now absolute) keeps the same casing.
        resolve(&mut c, Path::new("/")).unwrap();
        assert!(Arc::ptr_eq(&casing, c.loaded_casing.as_ref().unwrap()));
        // Missing, and in metres where millimetres are meant (0.2 mm across).
        let tmp = mocomp_testkit::TempDir::new("coil-casing");
        let metres = tmp.path("metres.stl");
        let bytes = std::fs::read(dir.join("MagStim_D70.stl")).unwrap();
        let facets = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        assert_eq!(
            bytes.len(),
            84 + 50 * facets,
            "the D70's casing is a binary STL"
        );
        std::fs::write(&metres, scaled_binary_stl(&bytes, 1e-3)).unwrap();
        for (file, says) in [
            (dir.join("no-such.stl"), "no-such.stl"),
            (PathBuf::from(metres), "0.2 mm across"),
        ] {
            let mut bad = CoilSection {
                casing: Some(file),
                ..CoilSection::default()
            };
            let e = resolve(&mut bad, &dir).unwrap_err().to_string();
            assert!(e.contains("coil.casing") && e.contains(says), "{e}");
        }
    }

    /// A binary STL's vertices times `k` (its 80-byte header, count, and 50-byte facets).
    fn scaled_binary_stl(bytes: &[u8], k: f32) -> Vec<u8> {
        let mut out = bytes.to_vec();
        for facet in out[84..].chunks_exact_mut(50) {
            for v in facet[12..48].chunks_exact_mut(4) {
                let x = f32::from_le_bytes([v[0], v[1], v[2], v[3]]) * k;
                v.copy_from_slice(&x.to_le_bytes());
            }
        }
        out
    }
}
