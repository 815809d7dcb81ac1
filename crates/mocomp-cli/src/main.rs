//! `mocomp`: keeps a tool carried by a Universal Robots arm at a goal pose relative to a tracked,
//! moving head. This binary wires the mocomp crates into subcommands; it computes nothing itself.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod args;
mod kin_cmd;

use clap::{Args, Parser, Subcommand};
use mocomp_kin::{KinError, Model};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// Motion compensation with a Universal Robots arm.
#[derive(Debug, Parser)]
#[command(name = "mocomp", version)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Forward kinematics: base_from_flange of a joint configuration (metres, radians).
    Fk {
        #[command(flatten)]
        arm: ArmArgs,
        /// Joint angles, radians, base to wrist 3.
        #[arg(long, value_name = "Q1,...,Q6", value_parser = args::six, allow_hyphen_values = true)]
        joints: [f64; 6],
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Inverse kinematics: every solution of a pose with its branch, and the one chosen.
    Ik {
        #[command(flatten)]
        arm: ArmArgs,
        /// Target pose as a UR pose vector: metres and rotation vector (of the tool if --tool).
        #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = args::six, allow_hyphen_values = true)]
        pose: [f64; 6],
        /// Current joints (radians): the choice is the solution nearest them, and their q6 is
        /// kept at a wrist singularity. Default: all zeros.
        #[arg(long, value_name = "Q1,...,Q6", value_parser = args::six, allow_hyphen_values = true)]
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
    },
    /// The model table: DH parameters, maximum joint speeds, control periods.
    Models {
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
}

/// The robot whose kinematics a command uses.
#[derive(Debug, Args)]
struct ArmArgs {
    /// Robot model (ur3, ur5, ur10, ur3e, ur5e, ur10e, ur16e, ur20, ur30).
    #[arg(long, value_parser = args::model)]
    robot: Model,
    /// Tool offset flange_from_tool as a UR pose vector (m, rotation vector).
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = args::six, allow_hyphen_values = true)]
    tool: Option<[f64; 6]>,
    /// The robot's own calibrated DH values (TOML; see README.md).
    #[arg(long, value_name = "FILE")]
    calibration: Option<PathBuf>,
}

impl ArmArgs {
    fn build(&self) -> anyhow::Result<mocomp_kin::Arm> {
        kin_cmd::arm(self.robot, self.calibration.as_deref(), self.tool)
    }
}

/// Exit code for bad input (arguments, files).
const EXIT_USAGE: u8 = 2;
/// Exit code for a well-formed request that cannot be met (an unreachable pose).
const EXIT_FAILURE: u8 = 1;

fn run(cli: Cli) -> anyhow::Result<()> {
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    match cli.command {
        Command::Fk { arm, joints, json } => {
            let has_tool = arm.tool.is_some();
            kin_cmd::fk(&mut out, &arm.build()?, &joints, has_tool, json)?;
        }
        Command::Ik {
            arm,
            pose,
            current,
            keep_branch,
            margin,
            angle_sum,
            json,
        } => {
            if !margin.is_finite() || margin < 0.0 {
                return Err(UsageError(format!(
                    "--margin {margin}: must be a finite, non-negative number of radians"
                ))
                .into());
            }
            let arm = arm.build()?;
            let choice = kin_cmd::IkChoice {
                current: current.unwrap_or([0.0; 6]),
                current_given: current.is_some(),
                keep_branch,
                margin,
                angle_sum,
            };
            kin_cmd::ik(&mut out, &arm, &pose, &choice, json)?;
        }
        Command::Models { json } => kin_cmd::models(&mut out, json)?,
    }
    out.flush()?;
    Ok(())
}

/// An error in what the user gave (exit code 2).
#[derive(Debug)]
struct UsageError(String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

fn exit_code(err: &anyhow::Error) -> u8 {
    if err.downcast_ref::<UsageError>().is_some() {
        return EXIT_USAGE;
    }
    // Errors about a pose that cannot be reached are outcomes, not bad input.
    match err.downcast_ref::<KinError>() {
        Some(
            KinError::Unreachable(_)
            | KinError::OutsideJointLimits { .. }
            | KinError::BranchUnavailable { .. }
            | KinError::NotConverged { .. },
        ) => EXIT_FAILURE,
        // Everything else comes from arguments or files the user gave.
        _ => EXIT_USAGE,
    }
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            use clap::error::ErrorKind;
            if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion)
                || e.kind() == ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            {
                // Help and version go to stdout (help on a bare `mocomp` to stderr, exit 2).
                let code = if e.use_stderr() { EXIT_USAGE } else { 0 };
                e.print().ok();
                return ExitCode::from(code);
            }
            // One line that names the argument: clap's message up to the usage hint, joined.
            let text = e.render().to_string();
            let line: Vec<&str> = text
                .lines()
                .take_while(|l| !l.trim().is_empty())
                .map(str::trim)
                .collect();
            eprintln!("{}", line.join(" "));
            return ExitCode::from(EXIT_USAGE);
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Broken pipe (e.g. `mocomp models | head -1`) is not an error worth reporting.
            if e.downcast_ref::<std::io::Error>()
                .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
            {
                return ExitCode::SUCCESS;
            }
            eprintln!("error: {e:#}");
            ExitCode::from(exit_code(&e))
        }
    }
}
