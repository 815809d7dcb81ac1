//! `mocomp fk`: forward kinematics, printed.

use crate::args::ArmArgs;
use anyhow::Result;
use clap::Args;
use mocomp_geom::{rows_from_iso, ur_pose_from_iso};
use mocomp_kin::Arm;
use serde::Serialize;
use std::io::Write;

#[derive(Serialize)]
struct FkJson {
    base_from_flange: [[f64; 4]; 4],
    pose: [f64; 6],
    #[serde(skip_serializing_if = "Option::is_none")]
    base_from_tool: Option<[[f64; 4]; 4]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tool_pose: Option<[f64; 6]>,
}

/// Forward kinematics: base_from_flange of a joint configuration (metres, radians).
#[derive(Debug, Clone, Args)]
pub struct FkCmd {
    #[command(flatten)]
    arm: ArmArgs,
    /// Joint angles, radians, base to wrist 3.
    #[arg(long, value_name = "Q1,...,Q6", value_parser = crate::args::six, allow_hyphen_values = true)]
    joints: [f64; 6],
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

impl FkCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let (arm, has_tool, json) = (self.arm.build()?, self.arm.tool.is_some(), self.json);
        print(out, &arm, &self.joints, has_tool, json)
    }
}

fn print(
    out: &mut dyn Write,
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
