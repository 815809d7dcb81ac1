//! [`solve`]: checks, the chosen solver, outliers, residuals, uncertainty.

use crate::checks::{CheckReport, check_pairs};
use crate::error::CalibError;
use crate::linear;
use crate::noise::NoiseModel;
use crate::pairs::Pair;
use crate::refine::{self, OUTLIER_THRESHOLD};
use crate::report::{CalibrationFile, PairResidual, ResidualSummary, TransformEntry, Uncertainty};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::units::{m_to_mm, rad_to_deg};
use std::fmt;
use std::str::FromStr;

/// Which solver (`"li"`, `"shah"`, `"refined"` in configuration files).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The seed paper's linear 24-unknown method, with the translation re-solve.
    Li,
    /// Shah's Kronecker-product method.
    Shah,
    /// Robust weighted nonlinear least squares on SE(3) from the better closed form (default).
    Refined,
}

impl Method {
    /// `"li"`, `"shah"`, `"refined"`.
    pub fn name(self) -> &'static str {
        match self {
            Method::Li => "li",
            Method::Shah => "shah",
            Method::Refined => "refined",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = CalibError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "li" => Ok(Method::Li),
            "shah" => Ok(Method::Shah),
            "refined" => Ok(Method::Refined),
            _ => Err(CalibError::InvalidOption(format!(
                "unknown method {s:?} (li, shah, refined)"
            ))),
        }
    }
}

/// Options of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveOptions {
    /// Solver.
    pub method: Method,
    /// Expected noise (weights and tolerances).
    pub noise: NoiseModel,
    /// Leave the outlier pairs out and solve again (otherwise they are only reported, and
    /// down-weighted by the refined solver).
    pub reject_outliers: bool,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            method: Method::Refined,
            noise: NoiseModel::default(),
            reject_outliers: false,
        }
    }
}

/// A calibration: X, Y and how well they fit.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// The solver used.
    pub method: Method,
    /// `X = flange_from_marker`.
    pub flange_from_marker: Isometry3<f64>,
    /// `Y = base_from_tracker`.
    pub base_from_tracker: Isometry3<f64>,
    /// Every pair's residual.
    pub residuals: Vec<PairResidual>,
    /// RMS translation residual over the pairs used, mm.
    pub rms_mm: f64,
    /// RMS rotation residual over the pairs used, degrees.
    pub rms_deg: f64,
    /// Largest translation residual over the pairs used, mm.
    pub max_mm: f64,
    /// Largest rotation residual over the pairs used, degrees.
    pub max_deg: f64,
    /// Indices of the pairs flagged as outliers.
    pub outliers: Vec<usize>,
    /// Condition number of the (scale-normalised) information matrix: how well the pose set
    /// determines X and Y (1 is ideal; thousands mean nearly degenerate).
    pub condition: f64,
    /// What the pre-solve checks found (rotation spread, suspect pairs).
    pub checks: CheckReport,
    /// 1σ uncertainty of X and Y.
    pub uncertainty: Uncertainty,
    /// Nonlinear iterations (0 for the closed forms).
    pub iterations: usize,
}

impl Calibration {
    /// The result file of this calibration.
    pub fn to_file(&self) -> CalibrationFile {
        CalibrationFile {
            method: self.method.name().to_string(),
            pairs: self.residuals.len(),
            x: TransformEntry::of(&self.flange_from_marker),
            y: TransformEntry::of(&self.base_from_tracker),
            residuals: ResidualSummary {
                rms_mm: self.rms_mm,
                rms_deg: self.rms_deg,
                max_mm: self.max_mm,
                max_deg: self.max_deg,
            },
            outliers: self
                .outliers
                .iter()
                .map(|&i| self.residuals[i].line.unwrap_or(i + 1))
                .collect(),
            uncertainty: self.uncertainty,
        }
    }
}

fn closed_form(
    method: Method,
    pairs: &[Pair],
    noise: &NoiseModel,
) -> Result<(Isometry3<f64>, Isometry3<f64>), CalibError> {
    match method {
        Method::Li => linear::li(pairs, true),
        Method::Shah => linear::shah(pairs),
        Method::Refined => {
            // The better of the two closed forms by the weighted cost.
            let li = linear::li(pairs, true);
            let shah = linear::shah(pairs);
            let score = |xy: &(Isometry3<f64>, Isometry3<f64>)| -> f64 {
                refine::norms(pairs, &xy.0, &xy.1, noise)
                    .iter()
                    .map(|r| r * r)
                    .sum()
            };
            match (li, shah) {
                (Ok(a), Ok(b)) => Ok(if score(&a) <= score(&b) { a } else { b }),
                (Ok(a), Err(_)) | (Err(_), Ok(a)) => Ok(a),
                (Err(e), Err(_)) => Err(e),
            }
        }
    }
}

fn fit(
    method: Method,
    pairs: &[Pair],
    noise: &NoiseModel,
) -> Result<(Isometry3<f64>, Isometry3<f64>, usize), CalibError> {
    let (x, y) = closed_form(method, pairs, noise)?;
    if method == Method::Refined {
        let r = refine::refine_robust(pairs, x, y, noise);
        Ok((r.x, r.y, r.iterations))
    } else {
        Ok((x, y, 0))
    }
}

/// Calibrates: checks the pair set (failing with a named reason when it is degenerate or not
/// rigid), solves with the chosen method, flags outlier pairs (and leaves them out and solves
/// again when asked), and reports residuals, conditioning and uncertainty.
pub fn solve(pairs: &[Pair], options: &SolveOptions) -> Result<Calibration, CalibError> {
    options.noise.validate()?;
    let checks = check_pairs(pairs, &options.noise)?;
    let noise = &options.noise;
    let mut used = vec![true; pairs.len()];
    let (mut x, mut y, mut iterations) = fit(options.method, pairs, noise)?;
    let mut outliers;
    let mut rounds = 0;
    loop {
        let norms = refine::norms(pairs, &x, &y, noise);
        let used_norms = selected(&norms, &used);
        let scale = refine::robust_scale(&used_norms);
        outliers = (0..pairs.len())
            .filter(|&i| norms[i] > OUTLIER_THRESHOLD * scale)
            .collect::<Vec<_>>();
        if !options.reject_outliers || rounds >= 5 {
            break;
        }
        let newly: Vec<usize> = outliers.iter().copied().filter(|&i| used[i]).collect();
        if newly.is_empty() {
            break;
        }
        for &i in &newly {
            used[i] = false;
        }
        let remaining = selected(pairs, &used);
        if remaining.len() < 3 {
            return Err(CalibError::TooManyOutliers {
                outliers: pairs.len() - remaining.len(),
                total: pairs.len(),
            });
        }
        let (nx, ny, it) = fit(options.method, &remaining, noise)?;
        x = nx;
        y = ny;
        iterations += it;
        rounds += 1;
    }

    // Residuals of every pair; statistics over the pairs used.
    let norms = refine::norms(pairs, &x, &y, noise);
    let mut residuals = Vec::with_capacity(pairs.len());
    let (mut sum_t2, mut sum_r2, mut max_t, mut max_r, mut n_used) = (0.0, 0.0, 0.0f64, 0.0f64, 0);
    for (i, p) in pairs.iter().enumerate() {
        let r = refine::residual(p, &x, &y);
        let t_mm = m_to_mm(r.translation.norm());
        let r_deg = rad_to_deg(r.rotation.norm());
        if used[i] {
            sum_t2 += t_mm * t_mm;
            sum_r2 += r_deg * r_deg;
            max_t = max_t.max(t_mm);
            max_r = max_r.max(r_deg);
            n_used += 1;
        }
        residuals.push(PairResidual {
            index: i,
            line: p.line,
            translation_mm: t_mm,
            rotation_deg: r_deg,
            normalized: norms[i],
            outlier: outliers.contains(&i),
            used: used[i],
        });
    }
    let n = n_used.max(1) as f64;

    // Uncertainty and conditioning from the information matrix of the pairs used.
    let used_pairs = selected(pairs, &used);
    let h = refine::information(&used_pairs, &x, &y, noise);
    let chi2: f64 = selected(&norms, &used).iter().map(|r| r * r).sum();
    let dof = (6 * used_pairs.len()).saturating_sub(12).max(1) as f64;
    let (uncertainty, condition) = uncertainty_and_condition(&h, chi2 / dof);
    Ok(Calibration {
        method: options.method,
        flange_from_marker: x,
        base_from_tracker: y,
        residuals,
        rms_mm: (sum_t2 / n).sqrt(),
        rms_deg: (sum_r2 / n).sqrt(),
        max_mm: max_t,
        max_deg: max_r,
        outliers,
        condition,
        checks,
        uncertainty,
        iterations,
    })
}

/// The items whose flag in `used` is set.
fn selected<T: Copy>(items: &[T], used: &[bool]) -> Vec<T> {
    items
        .iter()
        .zip(used)
        .filter(|(_, u)| **u)
        .map(|(v, _)| *v)
        .collect()
}

fn uncertainty_and_condition(h: &refine::Mat12, reduced_chi2: f64) -> (Uncertainty, f64) {
    let nan = Uncertainty {
        x_rotation_deg: f64::NAN,
        x_translation_mm: f64::NAN,
        y_rotation_deg: f64::NAN,
        y_translation_mm: f64::NAN,
    };
    // Condition of the scale-normalised information matrix D^-½ H D^-½.
    let d: Vec<f64> = (0..12).map(|k| h[(k, k)].max(1e-300).sqrt()).collect();
    let scaled = refine::Mat12::from_fn(|a, b| h[(a, b)] / (d[a] * d[b]));
    let eig = scaled.symmetric_eigen();
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in eig.eigenvalues.iter() {
        lo = lo.min(*v);
        hi = hi.max(*v);
    }
    let condition = if lo > 0.0 {
        (hi / lo).sqrt()
    } else {
        f64::INFINITY
    };
    let Some(inv) = h.try_inverse() else {
        return (nan, condition);
    };
    let c = inv * reduced_chi2;
    let block = |k: usize| {
        (c[(k, k)] + c[(k + 1, k + 1)] + c[(k + 2, k + 2)])
            .max(0.0)
            .sqrt()
    };
    (
        Uncertainty {
            x_rotation_deg: rad_to_deg(block(0)),
            x_translation_mm: m_to_mm(block(3)),
            y_rotation_deg: rad_to_deg(block(6)),
            y_translation_mm: m_to_mm(block(9)),
        },
        condition,
    )
}
