//! The configuration's range checks: one mechanism, each error naming the key.

use crate::AppError;

/// The range checks: one mechanism, each error naming the key.
#[derive(Debug, Clone, Copy)]
pub struct Check;

impl Check {
    /// `v` finite and within `[lo, hi]`; with `open_lo`, above `lo` rather than at least.
    pub fn range(key: &str, v: f64, lo: f64, hi: f64, open_lo: bool) -> Result<(), AppError> {
        let ok = v.is_finite() && (if open_lo { v > lo } else { v >= lo }) && v <= hi;
        if ok {
            return Ok(());
        }
        let left = if open_lo { "(" } else { "[" };
        let (lo_s, hi_s) = (fmt_bound(lo), fmt_bound(hi));
        Err(AppError::Config(format!(
            "{key} = {v}: must be in {left}{lo_s}, {hi_s}]"
        )))
    }

    /// `v` finite and above 0.
    pub fn positive(key: &str, v: f64) -> Result<(), AppError> {
        Self::range(key, v, 0.0, f64::INFINITY, true)
    }

    /// `v` finite and at least 0.
    pub fn non_negative(key: &str, v: f64) -> Result<(), AppError> {
        Self::range(key, v, 0.0, f64::INFINITY, false)
    }

    /// A whole number at least `lo`.
    pub fn at_least(key: &str, v: usize, lo: usize) -> Result<(), AppError> {
        if v >= lo {
            Ok(())
        } else {
            Err(AppError::Config(format!(
                "{key} = {v}: must be at least {lo}"
            )))
        }
    }
}

fn fmt_bound(v: f64) -> String {
    if v == f64::INFINITY {
        "∞".into()
    } else if (v - std::f64::consts::PI).abs() < 1e-15 {
        "π".into()
    } else {
        v.to_string()
    }
}
