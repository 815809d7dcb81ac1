//! `mocomp fk`, `mocomp ik` and `mocomp models`: printing what `mocomp-kin` computes.

use anyhow::{Context, Result};
use mocomp_geom::{iso_from_ur_pose, rows_from_iso, ur_pose_from_iso};
use mocomp_kin::{Arm, BranchPolicy, DhCalibration, MODELS, Metric, Model, Selection};
use serde::Serialize;
use std::io::Write;
use std::path::Path;

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

#[derive(Serialize)]
struct FkJson {
    base_from_flange: [[f64; 4]; 4],
    pose: [f64; 6],
    #[serde(skip_serializing_if = "Option::is_none")]
    base_from_tool: Option<[[f64; 4]; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tool_pose: Option<[f64; 6]>,
}

/// `mocomp fk`.
pub fn fk(
    out: &mut impl Write,
    arm: &Arm,
    joints: &[f64; 6],
    has_tool: bool,
    json: bool,
) -> Result<()> {
    let flange = arm.fk_flange(joints);
    let tool = arm.fk(joints);
    if json {
        let j = FkJson {
            base_from_flange: rows_from_iso(&flange),
            pose: ur_pose_from_iso(&flange),
            base_from_tool: has_tool.then(|| rows_from_iso(&tool)),
            tool_pose: has_tool.then(|| ur_pose_from_iso(&tool)),
        };
        writeln!(out, "{}", serde_json::to_string(&j)?)?;
        return Ok(());
    }
    let calibrated = if arm.is_calibrated() {
        ", calibrated"
    } else {
        ""
    };
    crate::print::transform(
        out,
        &format!("base_from_flange ({}{calibrated}; metres)", arm.model()),
        &flange,
        false,
    )?;
    writeln!(
        out,
        "pose [x, y, z, rx, ry, rz] (m, rad): [{}]",
        crate::print::row(&ur_pose_from_iso(&flange))
    )?;
    if has_tool {
        crate::print::transform(out, "base_from_tool (metres)", &tool, false)?;
        writeln!(
            out,
            "tool pose [x, y, z, rx, ry, rz] (m, rad): [{}]",
            crate::print::row(&ur_pose_from_iso(&tool))
        )?;
    }
    Ok(())
}

#[derive(Serialize)]
struct SolutionJson {
    joints: [f64; 6],
    shoulder: &'static str,
    elbow: &'static str,
    wrist: &'static str,
}

#[derive(Serialize)]
struct IkJson {
    solutions: Vec<SolutionJson>,
    chosen: [f64; 6],
    chosen_index: usize,
    singular: Vec<&'static str>,
}

/// Options of `mocomp ik` that decide the choice.
#[derive(Debug, Clone, Copy)]
pub struct IkChoice {
    /// Joints to move from (zeros when not given).
    pub current: [f64; 6],
    /// Whether `--current` was given.
    pub current_given: bool,
    /// Only solutions on the branch of `current`.
    pub keep_branch: bool,
    /// Joint-limit margin, radians.
    pub margin: f64,
    /// Rank by the seed paper's sum of |Δq| instead of time to reach.
    pub angle_sum: bool,
}

/// `mocomp ik`. Returns an error (exit code 1) when the pose has no acceptable solution.
pub fn ik(
    out: &mut impl Write,
    arm: &Arm,
    pose: &[f64; 6],
    choice: &IkChoice,
    json: bool,
) -> Result<()> {
    let target = iso_from_ur_pose(pose).context("--pose")?;
    let sols = arm.ik(&target, choice.current[5])?;
    let selection = Selection {
        metric: if choice.angle_sum {
            Metric::WeightedSum([1.0; 6])
        } else {
            Metric::TimeToReach
        },
        branch: if choice.keep_branch {
            BranchPolicy::KeepCurrent
        } else {
            BranchPolicy::Any
        },
        limit_margin: choice.margin,
    };
    let chosen = arm.choose(&sols, &choice.current, &selection)?;
    let mut singular = Vec::new();
    if sols.singular.shoulder {
        singular.push("shoulder");
    }
    if sols.singular.elbow {
        singular.push("elbow");
    }
    if sols.singular.wrist {
        singular.push("wrist");
    }
    if json {
        let j = IkJson {
            solutions: sols
                .iter()
                .map(|s| SolutionJson {
                    joints: s.joints,
                    shoulder: s.branch.shoulder.as_str(),
                    elbow: s.branch.elbow.as_str(),
                    wrist: s.branch.wrist.as_str(),
                })
                .collect(),
            chosen: chosen.joints,
            chosen_index: chosen.index,
            singular,
        };
        writeln!(out, "{}", serde_json::to_string(&j)?)?;
        return Ok(());
    }
    writeln!(
        out,
        "{}: {} solution{} (radians), * = chosen",
        arm.model(),
        sols.len(),
        if sols.len() == 1 { "" } else { "s" }
    )?;
    writeln!(
        out,
        "     shoulder elbow wrist  {:>10} {:>10} {:>10} {:>10} {:>10} {:>10}",
        "q1", "q2", "q3", "q4", "q5", "q6"
    )?;
    for (i, s) in sols.iter().enumerate() {
        writeln!(
            out,
            "{} {:>2} {:<8} {:<5} {:<6} {}",
            if i == chosen.index { "*" } else { " " },
            i + 1,
            s.branch.shoulder.as_str(),
            s.branch.elbow.as_str(),
            s.branch.wrist.as_str(),
            crate::print::row(&s.joints)
        )?;
    }
    let from = if choice.current_given {
        "--current"
    } else {
        "the zero configuration (no --current given)"
    };
    let metric = if choice.angle_sum {
        format!("sum of |Δq| {:.4} rad", chosen.cost)
    } else {
        format!("time to reach {:.4} s", chosen.cost)
    };
    writeln!(
        out,
        "chosen: #{} as [{}] (nearest ±2π variant to {from}; {metric})",
        chosen.index + 1,
        crate::print::row(&chosen.joints)
    )?;
    if !singular.is_empty() {
        writeln!(
            out,
            "note: singular ({}); merged solutions are listed once{}",
            singular.join(", "),
            if sols.singular.wrist {
                ", q6 taken from --current where reachable"
            } else {
                ""
            }
        )?;
    }
    Ok(())
}

#[derive(Serialize)]
struct ModelJson {
    name: &'static str,
    d1: f64,
    a2: f64,
    a3: f64,
    d4: f64,
    d5: f64,
    d6: f64,
    max_speed_rad_s: [f64; 6],
    lower_limits_rad: [Option<f64>; 6],
    upper_limits_rad: [Option<f64>; 6],
    control_period_s: f64,
}

/// `mocomp models`: the model table.
pub fn models(out: &mut impl Write, json: bool) -> Result<()> {
    let finite = |v: &[f64; 6]| v.map(|x| x.is_finite().then_some(x));
    if json {
        let rows: Vec<ModelJson> = MODELS
            .iter()
            .map(|m| ModelJson {
                name: m.name,
                d1: m.geometry.d1,
                a2: m.geometry.a2,
                a3: m.geometry.a3,
                d4: m.geometry.d4,
                d5: m.geometry.d5,
                d6: m.geometry.d6,
                max_speed_rad_s: m.max_speed,
                lower_limits_rad: finite(&m.lower_limits),
                upper_limits_rad: finite(&m.upper_limits),
                control_period_s: m.series.period_s(),
            })
            .collect();
        writeln!(out, "{}", serde_json::to_string(&rows)?)?;
        return Ok(());
    }
    writeln!(
        out,
        "model  {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}  max joint speed (deg/s)    period",
        "d1 (m)", "a2", "a3", "d4", "d5", "d6"
    )?;
    for m in &MODELS {
        let g = &m.geometry;
        let speeds: Vec<String> = m
            .max_speed
            .iter()
            .map(|v| format!("{:.0}", v.to_degrees()))
            .collect();
        writeln!(
            out,
            "{:<6} {:>8.5} {:>8.5} {:>8.5} {:>8.5} {:>8.5} {:>8.5}  {:<26} {:.0} ms",
            m.name,
            g.d1,
            g.a2,
            g.a3,
            g.d4,
            g.d5,
            g.d6,
            speeds.join(","),
            m.series.period_s() * 1000.0
        )?;
    }
    writeln!(
        out,
        "joint limits: ±360° on every joint; UR3/UR3e wrist 3 turns without limit"
    )?;
    Ok(())
}
