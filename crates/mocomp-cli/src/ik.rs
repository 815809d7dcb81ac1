//! `mocomp ik`: every inverse kinematics solution of a pose, and the one chosen, printed.

use crate::args::ArmArgs;
use anyhow::{Context, Result};
use clap::Args;
use mocomp_geom::iso_from_ur_pose;
use mocomp_kin::{Arm, BranchPolicy, Metric, Selection};
use serde::Serialize;
use std::io::Write;

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
        let sols = arm.ik(&target, current[5])?;
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
        let chosen = arm.choose(&sols, &current, &selection)?;
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
        if self.json {
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
        let from = if self.current.is_some() {
            "--current"
        } else {
            "the zero configuration (no --current given)"
        };
        let metric = if self.angle_sum {
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
}
