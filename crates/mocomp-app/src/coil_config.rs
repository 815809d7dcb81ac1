//! `[coil]`: the coil's solid for the clearance and its field model (the `.ccd` file, the
//! stimulator's dI/dt and the default target depth), checked and read into a [`DoseModel`].

use crate::AppError;
use crate::capped_file::read_capped_text;
use crate::config_check::Check;
use mocomp_efield::{DipoleCoil, DoseModel, parse_ccd};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// `[coil]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CoilSection {
    /// Radius seen from the head, m.
    pub radius_m: f64,
    /// Thickness behind the face, m.
    pub thickness_m: f64,
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

/// `model`'s path relative to `dir`, made absolute (the file must exist).
pub fn resolve(c: &mut CoilSection, dir: &Path) -> Result<(), AppError> {
    let Some(model) = &c.model else {
        return Ok(());
    };
    let path = dir.join(model);
    let absolute = std::fs::canonicalize(&path)
        .map_err(|e| AppError::Config(format!("coil.model = {}: {e}", path.display())))?;
    c.model = Some(absolute);
    Ok(())
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
}
