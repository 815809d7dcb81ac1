//! Value parsers for command-line arguments. Each error is one line that clap prefixes with the
//! argument's name.

use anyhow::{Context, Result};
use clap::Args;
use mocomp_geom::iso_from_ur_pose;
use mocomp_kin::{Arm, DhCalibration, Model};
use std::path::{Path, PathBuf};

/// The robot whose kinematics a command uses.
#[derive(Debug, Clone, Args)]
pub struct ArmArgs {
    /// Robot model (ur3, ur5, ur10, ur3e, ur5e, ur10e, ur16e, ur20, ur30).
    #[arg(long, value_parser = model)]
    pub robot: Model,
    /// Tool offset flange_from_tool as a UR pose vector (m, rotation vector).
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = six, allow_hyphen_values = true)]
    pub tool: Option<[f64; 6]>,
    /// The robot's own calibrated DH values (TOML; see the book's commands page, book/src/reference/commands.md).
    #[arg(long, value_name = "FILE")]
    pub calibration: Option<PathBuf>,
}

impl ArmArgs {
    /// The arm.
    pub fn build(&self) -> Result<Arm> {
        arm(self.robot, self.calibration.as_deref(), self.tool)
    }
}

/// Parses exactly `N` comma-separated finite numbers.
pub fn numbers<const N: usize>(s: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != N {
        return Err(format!(
            "expected {N} comma-separated numbers, got {}",
            parts.len()
        ));
    }
    let mut out = [0.0; N];
    for (i, (slot, text)) in out.iter_mut().zip(parts.iter()).enumerate() {
        let v: f64 = text
            .parse()
            .map_err(|_| format!("element {} ({text:?}) is not a number", i + 1))?;
        if !v.is_finite() {
            return Err(format!(
                "element {} ({text:?}) is not a finite number",
                i + 1
            ));
        }
        *slot = v;
    }
    Ok(out)
}

/// Six numbers (joints, or a UR pose vector).
pub fn six(s: &str) -> Result<[f64; 6], String> {
    numbers::<6>(s)
}

/// Three numbers (a point).
pub fn three(s: &str) -> Result<[f64; 3], String> {
    numbers::<3>(s)
}

/// Two non-negative numbers: a noise level in millimetres and degrees.
pub fn noise_pair(s: &str) -> Result<[f64; 2], String> {
    let v = numbers::<2>(s)?;
    if v.iter().any(|x| *x < 0.0) {
        return Err("noise levels must not be negative".into());
    }
    Ok(v)
}

/// A robot model name.
pub fn model(s: &str) -> Result<Model, String> {
    s.parse::<Model>().map_err(|e| e.to_string())
}

/// A demo controller by name (`paper`, `mocomp`, `oracle`).
pub fn controller(s: &str) -> Result<mocomp_app::experiment::Controller, String> {
    mocomp_app::experiment::Controller::from_name(s)
        .ok_or_else(|| format!("{s:?}: one of paper, mocomp, oracle"))
}

/// Builds the arm from the command line's robot, calibration file and tool.
pub fn arm(model: Model, calibration: Option<&Path>, tool: Option<[f64; 6]>) -> Result<Arm> {
    let mut arm = match calibration {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("--calibration {}: cannot read", path.display()))?;
            let cal = DhCalibration::from_toml_str(&text)
                .with_context(|| format!("--calibration {}", path.display()))?;
            if cal.model != model {
                return Err(crate::UsageError(format!(
                    "--calibration {}: the file is for a {}, but --robot is {}",
                    path.display(),
                    cal.model,
                    model
                ))
                .into());
            }
            Arm::calibrated(&cal).with_context(|| format!("--calibration {}", path.display()))?
        }
        None => Arm::new(model),
    };
    if let Some(t) = tool {
        arm = arm.with_tool(iso_from_ur_pose(&t).context("--tool")?);
    }
    Ok(arm)
}

/// A pose argument as a transform; `name` is the option, for the error.
pub fn pose(name: &str, v: &[f64; 6]) -> Result<mocomp_geom::nalgebra::Isometry3<f64>> {
    iso_from_ur_pose(v).map_err(|e| crate::UsageError(format!("{name}: {e}")).into())
}

/// A positive, finite number of seconds (or anything else), or the usage error naming `name`.
pub fn positive(name: &str, v: f64) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(crate::UsageError(format!("{name} {v}: must be a positive number")).into())
    }
}

/// A positive, finite number (a duration in seconds, say), as clap parses a value.
pub fn positive_number(s: &str) -> std::result::Result<f64, String> {
    number_where(s, |v| v > 0.0, "must be a positive number")
}

/// A rate in (0, 10000] Hz, as clap parses a value.
pub fn rate_hz(s: &str) -> std::result::Result<f64, String> {
    number_where(s, |v| v > 0.0 && v <= 10_000.0, "must be in (0, 10000] Hz")
}

/// A finite number for which `holds` is true, or the error saying `rule`.
fn number_where(
    s: &str,
    holds: impl Fn(f64) -> bool,
    rule: &str,
) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && holds(v) => Ok(v),
        Ok(v) => Err(format!("{v}: {rule}")),
        Err(e) => Err(format!("{s:?}: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_positive_number_is_finite_and_above_zero() {
        assert_eq!(positive_number("2.5"), Ok(2.5));
        for bad in ["0", "-1", "inf", "NaN", "two"] {
            assert!(positive_number(bad).is_err(), "{bad}");
        }
        assert_eq!(rate_hz("10000"), Ok(10_000.0));
        assert!(rate_hz("10000.5").is_err());
    }

    #[test]
    fn parses_and_rejects() {
        assert_eq!(six("1, 2,3,4,5,6e-1").unwrap()[5], 0.6);
        assert!(six("1,2,3").unwrap_err().contains("got 3"));
        assert!(six("1,2,x,4,5,6").unwrap_err().contains("element 3"));
        assert!(six("1,2,3,4,5,NaN").unwrap_err().contains("not a finite"));
        assert!(six("1,2,3,4,5,inf").unwrap_err().contains("not a finite"));
        assert!(model("ur7").unwrap_err().contains("known"));
        assert_eq!(model("UR10e").unwrap(), Model::Ur10e);
    }
}

/// An Azure Kinect depth mode, as the command line names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DepthModeArg {
    /// 320×288, narrow field of view, 2×2 binned.
    NfovBinned,
    /// 640×576, narrow field of view.
    NfovUnbinned,
    /// 512×512, wide field of view, 2×2 binned.
    WfovBinned,
    /// 1024×1024, wide field of view (at most 15 frames a second).
    WfovUnbinned,
}

impl DepthModeArg {
    /// The SDK's mode.
    pub fn mode(self) -> mocomp_k4a::DepthMode {
        use mocomp_k4a::DepthMode as M;
        match self {
            Self::NfovBinned => M::NfovBinned,
            Self::NfovUnbinned => M::NfovUnbinned,
            Self::WfovBinned => M::WfovBinned,
            Self::WfovUnbinned => M::WfovUnbinned,
        }
    }
}
