//! `mocomp ik`: every inverse kinematics solution of a pose, and the one chosen, printed.

use crate::args::ArmArgs;
use anyhow::{Context, Result};
use clap::Args;
use mocomp_geom::iso_from_ur_pose;
use mocomp_kin::report::IkReport;
use mocomp_kin::{Arm, BranchPolicy, Metric, Selection};
use std::io::Write;

/// Inverse kinematics: every solution of a pose with its branch, and the one chosen.
#[derive(Debug, Clone, Args)]
pub struct IkCmd {
    #[command(flatten)]
    arm: ArmArgs,
    /// Target pose as a UR pose vector: metres and rotation vector (of the tool if --tool).
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = crate::args::six, allow_hyphen_values = true)]
    pose: [f64; 6],
    /// Current joints (radians): the choice is the solution nearest them, and their q6 is kept
    /// at a wrist singularity. Default: all zeros.
    #[arg(long, value_name = "Q1,...,Q6", value_parser = crate::args::six, allow_hyphen_values = true)]
    current: Option<[f64; 6]>,
    /// Choose only on the branch of --current (as the control loop does while tracking).
    #[arg(long)]
    keep_branch: bool,
    /// Keep this far (radians) inside every joint limit.
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "RAD",
        allow_negative_numbers = true
    )]
    margin: f64,
    /// Rank by the seed paper's minimal sum of |Δq| instead of time to reach.
    #[arg(long)]
    angle_sum: bool,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

impl IkCmd {
    /// Runs it. An error (exit code 1) when the pose has no acceptable solution.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        if !self.margin.is_finite() || self.margin < 0.0 {
            return Err(crate::UsageError(format!(
                "--margin {}: must be a finite, non-negative number of radians",
                self.margin
            ))
            .into());
        }
        let arm = self.arm.build()?;
        self.print(out, &arm)
    }

    fn print(&self, out: &mut dyn Write, arm: &Arm) -> Result<()> {
        let current = self.current.unwrap_or([0.0; 6]);
        let target = iso_from_ur_pose(&self.pose).context("--pose")?;
        let selection = Selection {
            metric: if self.angle_sum {
                Metric::WeightedSum([1.0; 6])
            } else {
                Metric::TimeToReach
            },
            branch: if self.keep_branch {
                BranchPolicy::KeepCurrent
            } else {
                BranchPolicy::Any
            },
            limit_margin: self.margin,
        };
        let r = IkReport::solve(arm, &target, &current, self.current.is_some(), &selection)?;
        crate::print::report(out, &r, self.json)
    }
}
