//! `mocomp efield`: the electric field a coil model induces at points in a sphere, for a coil
//! pose as SimNIBS gives one (`matsimnibs`, mm) — a calculator, as `fk` is for the arm. The coil
//! file and the points file are read here with size limits; the field is `mocomp-efield`'s.

use crate::AppError;
use crate::config::Setup;
use crate::files::capped::read_capped_text;
use mocomp_efield::{FIT_RADIUS_M, PlacedCoil, Sphere, local_sphere};
use mocomp_geom::nalgebra::{Isometry3, Matrix4, Point3};
use mocomp_geom::units::mm_to_m;
use mocomp_head::Reframed;
use serde::Serialize;
use std::path::Path;

/// The largest points file read, bytes.
pub const MAX_POINTS_BYTES: u64 = 64 << 20;
/// How far the pose's rotation may be from orthonormal (max |RᵀR − I|): SimNIBS writes
/// matsimnibs to full precision.
const RIGID_TOLERANCE: f64 = 1e-6;

/// What to compute.
#[derive(Debug, Clone)]
pub struct Request<'a> {
    /// The `.ccd` file.
    pub coil: &'a Path,
    /// image_from_coil as SimNIBS's `matsimnibs`, row by row, mm.
    pub matsimnibs: [f64; 16],
    /// The sphere the head is taken to be.
    pub head: HeadSource<'a>,
    /// Points given one by one, mm.
    pub at_mm: Vec<[f64; 3]>,
    /// A CSV of points (`x,y,z` in mm a line; a header line is allowed).
    pub points: Option<&'a Path>,
    /// dI/dt, A/µs (without it: the file's `dIdtmax`, the stimulator at full output).
    pub didt_a_per_us: Option<f64>,
}

/// Where the sphere comes from.
#[derive(Debug, Clone, Copy)]
pub enum HeadSource<'a> {
    /// Given: centre and radius, mm (image frame).
    Sphere([f64; 4]),
    /// Fitted to the scalp of this configuration's head under the coil
    /// ([`mocomp_efield::local_sphere`]), in the image's frame through `[head] head_from_image`.
    Config(&'a Path),
}

/// The sphere used, as reported.
#[derive(Debug, Clone, Serialize)]
pub struct SphereReport {
    /// Centre and radius, mm.
    pub sphere_mm: [f64; 4],
    /// "given", or "scalp" when fitted under the coil.
    pub from: &'static str,
    /// Fitted: the patch's radius, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_radius_mm: Option<f64>,
    /// Fitted: the scalp points' RMS distance from the sphere, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rms_mm: Option<f64>,
}

/// The field at one point.
#[derive(Debug, Clone, Serialize)]
pub struct PointField {
    /// Where, mm.
    pub at_mm: [f64; 3],
    /// The field, V/m.
    #[serde(rename = "E_V_per_m")]
    pub e_v_per_m: [f64; 3],
}

/// The answer.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The coil file.
    pub coil: String,
    /// Its dipoles.
    pub dipoles: usize,
    /// The dI/dt used, A/µs.
    pub didt_a_per_us: f64,
    /// The sphere.
    pub sphere: SphereReport,
    /// Each point.
    pub points: Vec<PointField>,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{} ({} dipoles), dI/dt {:.2} A/µs",
            self.coil, self.dipoles, self.didt_a_per_us
        )?;
        let [x, y, z, r] = self.sphere.sphere_mm;
        write!(
            f,
            "sphere: centre {x:.2},{y:.2},{z:.2} mm, radius {r:.2} mm"
        )?;
        match (self.sphere.fit_radius_mm, self.sphere.rms_mm) {
            (Some(patch), Some(rms)) => writeln!(
                f,
                " (fitted to the scalp within {patch:.0} mm of the point under the coil, RMS {rms:.2} mm)"
            )?,
            _ => writeln!(f)?,
        }
        writeln!(f, "| x (mm) | y | z | Ex (V/m) | Ey | Ez | |E| |")?;
        writeln!(f, "|---|---|---|---|---|---|---|")?;
        for p in &self.points {
            let [x, y, z] = p.at_mm;
            let [ex, ey, ez] = p.e_v_per_m;
            let n = (ex * ex + ey * ey + ez * ez).sqrt();
            writeln!(
                f,
                "| {x:.2} | {y:.2} | {z:.2} | {ex:.3} | {ey:.3} | {ez:.3} | {n:.3} |"
            )?;
        }
        Ok(())
    }
}

/// Points from a CSV: `x,y,z` (mm) a line, a first line that is not numbers taken as a header,
/// blank lines skipped; a bad line named.
pub fn parse_points(file: &str, text: &str) -> Result<Vec<[f64; 3]>, AppError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        let numbers: Option<Vec<f64>> = fields
            .iter()
            .map(|f| f.parse::<f64>().ok().filter(|v| v.is_finite()))
            .collect();
        match numbers {
            Some(v) if v.len() == 3 => out.push([v[0], v[1], v[2]]),
            None if i == 0 => continue,
            _ => {
                return Err(AppError::Config(format!(
                    "{file}:{}: {line:?}: a point is x,y,z in mm, three finite numbers",
                    i + 1
                )));
            }
        }
    }
    Ok(out)
}

/// The field at each point.
pub fn compute(req: &Request<'_>) -> Result<Report, AppError> {
    let coil = crate::config::coil::read_coil(req.coil)?;
    let m = Matrix4::from_row_slice(&req.matsimnibs);
    let image_from_coil = mocomp_geom::iso_from_matrix_mm(&m, RIGID_TOLERANCE)
        .map_err(|e| AppError::Config(format!("--pose: not a coil pose: {e}")))?;
    let (sphere, report) = sphere(req.head, &image_from_coil)?;
    let didt_a_per_us = match (req.didt_a_per_us, coil.didt_max_a_per_s) {
        (Some(d), _) if d.is_finite() && d > 0.0 => d,
        (Some(d), _) => {
            return Err(AppError::Config(format!(
                "--didt {d}: a positive number of A/µs"
            )));
        }
        (None, Some(max)) => max * 1e-6,
        (None, None) => {
            return Err(AppError::Config(format!(
                "{}: no dIdtmax in its header: give --didt (A/µs)",
                req.coil.display()
            )));
        }
    };
    let mut points = req.at_mm.clone();
    if let Some(p) = req.points {
        let text = read_capped_text(p, MAX_POINTS_BYTES, "a points file")?;
        points.extend(parse_points(&p.display().to_string(), &text)?);
    }
    if points.is_empty() {
        return Err(AppError::Config(
            "no point: give --at X,Y,Z (mm) or --points FILE.csv".into(),
        ));
    }
    let mut placed = PlacedCoil::with_capacity(coil.len());
    placed
        .place(&coil, &image_from_coil, &sphere)
        .map_err(|e| AppError::Config(format!("--pose with --sphere: {e}")))?;
    let didt = didt_a_per_us * 1e6;
    let fields = points
        .iter()
        .map(|at| {
            let p = Point3::new(mm_to_m(at[0]), mm_to_m(at[1]), mm_to_m(at[2]));
            let e = placed.e_field(&p, didt).map_err(|e| {
                AppError::Config(format!(
                    "the point {:.2},{:.2},{:.2} mm: {e}",
                    at[0], at[1], at[2]
                ))
            })?;
            Ok(PointField {
                at_mm: *at,
                e_v_per_m: [e.x, e.y, e.z],
            })
        })
        .collect::<Result<Vec<_>, AppError>>()?;
    Ok(Report {
        coil: req.coil.display().to_string(),
        dipoles: coil.len(),
        didt_a_per_us,
        sphere: report,
        points: fields,
    })
}

/// The sphere `head` gives for the coil at `image_from_coil`.
fn sphere(
    head: HeadSource<'_>,
    image_from_coil: &Isometry3<f64>,
) -> Result<(Sphere, SphereReport), AppError> {
    match head {
        HeadSource::Sphere([cx, cy, cz, r]) => {
            let sphere = Sphere::new(
                Point3::new(mm_to_m(cx), mm_to_m(cy), mm_to_m(cz)),
                mm_to_m(r),
            )
            .map_err(|e| AppError::Config(format!("--sphere: {e}")))?;
            Ok((
                sphere,
                SphereReport {
                    sphere_mm: [cx, cy, cz, r],
                    from: "given",
                    fit_radius_mm: None,
                    rms_mm: None,
                },
            ))
        }
        HeadSource::Config(path) => {
            let setup = Setup::load(path)?;
            let head = setup.file.head_model()?;
            let image_from_head = setup.file.head.head_from_image.iso().inverse();
            let scalp = Reframed::new(head.shape(), image_from_head);
            let local = local_sphere(&scalp, image_from_coil, FIT_RADIUS_M).map_err(|e| {
                AppError::Config(format!(
                    "{}: no sphere under the coil at --pose: {e}",
                    path.display()
                ))
            })?;
            let c = local.sphere.centre.coords * 1e3;
            Ok((
                local.sphere,
                SphereReport {
                    sphere_mm: [c.x, c.y, c.z, local.sphere.radius * 1e3],
                    from: "scalp",
                    fit_radius_mm: Some(FIT_RADIUS_M * 1e3),
                    rms_mm: Some(local.rms_m * 1e3),
                },
            ))
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn points_read_with_or_without_a_header_and_a_bad_line_is_named() {
        let p = parse_points("p.csv", "x,y,z\n1,2,3\n\n-4, 5.5 ,6\n").unwrap();
        assert_eq!(p, vec![[1.0, 2.0, 3.0], [-4.0, 5.5, 6.0]]);
        let e = parse_points("p.csv", "1,2,3\n4,5\n").unwrap_err();
        assert!(e.to_string().starts_with("p.csv:2:"), "{e}");
        let e = parse_points("p.csv", "x,y,z\nx,y,z\n").unwrap_err();
        assert!(e.to_string().starts_with("p.csv:2:"), "{e}");
    }
}
