//! `mocomp`: keeps a tool carried by a Universal Robots arm at a goal pose relative to a tracked,
//! moving head. This binary parses, calls the mocomp crates (`mocomp-app` for everything with a
//! session) and prints; it computes nothing itself. One file per subcommand, each a clap struct
//! with a `run`.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod args;
mod calibrate;
mod config;
mod dashboard;
mod demo;
mod efield;
mod fk;
mod head;
mod ik;
mod listen;
mod models;
mod placement;
mod pointer;
mod print;
mod register;
mod robot;
mod run;
mod serve_poses;
mod session;
mod targets;
mod teach_goal;
mod track;
mod ursim;

use clap::{Parser, Subcommand};
use std::io::Write;
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
    Fk(fk::FkCmd),
    Efield(efield::EfieldCmd),
    Ik(ik::IkCmd),
    Models(models::ModelsCmd),
    Listen(listen::ListenCmd),
    ServePoses(serve_poses::ServePosesCmd),
    Track(track::TrackCmd),
    Ursim(ursim::UrsimCmd),
    Run(run::RunCmd),
    Demo(Box<demo::DemoCmd>),
    TeachGoal(teach_goal::TeachCmd),
    Targets(targets::TargetsCmd),
    Placement(placement::PlacementCmd),
    Config(config::ConfigCmd),
    Robot(robot::RobotCmd),
    Calibrate(calibrate::CalibrateCmd),
    Head(head::HeadCmd),
    Pointer(pointer::PointerCmd),
    Register(register::RegisterCmd),
    Session(session::SessionCmd),
}

/// Exit code for bad input (arguments, files).
const EXIT_USAGE: u8 = 2;
/// Exit code for a well-formed request that cannot be met (an unreachable pose).
const EXIT_FAILURE: u8 = 1;

fn run(cli: Cli) -> anyhow::Result<()> {
    let stdout = std::io::stdout();
    let mut lock = stdout.lock();
    let out: &mut dyn Write = &mut lock;
    match cli.command {
        Command::Fk(c) => c.run(out)?,
        Command::Efield(c) => c.run(out)?,
        Command::Ik(c) => c.run(out)?,
        Command::Models(c) => c.run(out)?,
        Command::Listen(c) => c.run(out)?,
        Command::ServePoses(c) => c.run(out)?,
        Command::Track(c) => c.run(out)?,
        Command::Ursim(c) => c.run(out)?,
        Command::Run(c) => c.run(out)?,
        Command::Demo(c) => c.run(out)?,
        Command::TeachGoal(c) => c.run(out)?,
        Command::Targets(c) => c.run(out)?,
        Command::Placement(c) => c.run(out)?,
        Command::Config(c) => c.run(out)?,
        Command::Robot(c) => c.run(out)?,
        Command::Calibrate(c) => c.run(out)?,
        Command::Head(c) => c.run(out)?,
        Command::Pointer(c) => c.run(out)?,
        Command::Register(c) => c.run(out)?,
        Command::Session(c) => c.run(out)?,
    }
    out.flush()?;
    Ok(())
}

/// An error in what the user gave (exit code 2).
#[derive(Debug)]
pub(crate) struct UsageError(pub(crate) String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// Exit 2 for bad input (an argument, a file, a configuration value), 1 for everything that
/// fails at run time. Each error in the cause chain is asked in turn; the first that knows says.
/// An error nobody classifies is a run-time failure: calling a broken robot or a full disk "bad
/// input" would send the user to check arguments that are fine.
fn exit_code(err: &anyhow::Error) -> u8 {
    use mocomp_app::blame::{Blame, classify};
    err.chain()
        .find_map(|e| {
            if e.is::<UsageError>() {
                Some(EXIT_USAGE)
            } else {
                classify(e).map(|b| match b {
                    Blame::Input => EXIT_USAGE,
                    Blame::Run => EXIT_FAILURE,
                })
            }
        })
        .unwrap_or(EXIT_FAILURE)
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

#[cfg(test)]
mod exit_code_tests {
    #![allow(clippy::unwrap_used)] // test code
    use super::*;

    #[test]
    fn bad_input_is_2_and_everything_failing_at_run_time_is_1() {
        let usage = anyhow::Error::new(UsageError("--seconds: must be positive".into()));
        assert_eq!(exit_code(&usage), EXIT_USAGE);
        // Wrapped in context, the cause still decides.
        assert_eq!(exit_code(&usage.context("demo")), EXIT_USAGE);
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert_eq!(
            exit_code(&anyhow::Error::new(missing).context("--config f.toml")),
            EXIT_USAGE
        );
        let full = std::io::Error::from(std::io::ErrorKind::StorageFull);
        assert_eq!(exit_code(&anyhow::Error::new(full)), EXIT_FAILURE);
        assert_eq!(exit_code(&anyhow::anyhow!("something odd")), EXIT_FAILURE);
    }
}
