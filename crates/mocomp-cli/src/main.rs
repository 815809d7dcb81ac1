//! `mocomp`: keeps a tool carried by a Universal Robots arm at a goal pose relative to a tracked,
//! moving head. This binary wires the mocomp crates into subcommands; it computes nothing itself.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod args;
mod calib_cmd;
mod collect_cmd;
mod config_cmd;
mod demo_cmd;
mod igtl_cmd;
mod kin_cmd;
mod print;
mod robot_cmd;
mod run_cmd;
mod teach_cmd;
mod track_cmd;

use clap::{Args, Parser, Subcommand};
use mocomp_kin::{KinError, Model};
use std::io::Write;
use std::net::IpAddr;
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
    /// Print the poses an OpenIGTLink server streams (PLUS, 3D Slicer, a tracker), as received.
    Listen {
        /// Server address.
        #[arg(long, value_name = "HOST:PORT")]
        igtl: String,
        /// Device name (TRANSFORM device or TDATA tool), e.g. PLUS's HeadToTracker.
        #[arg(long, default_value = "HeadToTracker")]
        device: String,
        /// Stop after this many poses.
        #[arg(long)]
        count: Option<u64>,
        /// Give up when no pose arrives for this many seconds.
        #[arg(long, default_value_t = 10.0)]
        timeout: f64,
        /// Ask the server for a TDATA stream (STT_TDATA) after connecting.
        #[arg(long)]
        stt_tdata: bool,
        /// One JSON line per pose: {"device", "t", "valid", "tracker_from_marker": [[4×4, mm]]}.
        #[arg(long)]
        json: bool,
    },
    /// Serve poses over OpenIGTLink (TRANSFORM messages) from a file or a simulated head.
    ServePoses {
        /// Port to listen on (PLUS and Slicer use 18944).
        #[arg(long, default_value_t = 18944)]
        igtl_port: u16,
        /// Address to bind.
        #[arg(long, default_value = "127.0.0.1")]
        host: String,
        /// "sim" (a gently moving head), or a JSON-lines file with "tracker_from_marker" (4×4, mm),
        /// such as `mocomp listen --json` output.
        #[arg(long, value_name = "FILE|sim")]
        from: String,
        /// Device name.
        #[arg(long, default_value = "HeadToTracker")]
        device: String,
        /// Poses per second.
        #[arg(long, default_value_t = 60.0)]
        rate: f64,
        /// Stop after this many (default: the file once; forever for sim).
        #[arg(long)]
        count: Option<u64>,
        /// Header version: 1, or 2 with TransformStatus metadata (as PLUS and Slicer send).
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u16).range(1..=2))]
        header_version: u16,
    },
    /// Fiducial tracking in IR + depth frames (directories of 16-bit PNG pairs).
    Track(TrackCli),
    /// A simulated UR controller on the standard ports of a loopback address (RTDE 30004,
    /// dashboard 29999, script 30001–30003), for mocomp or any UR client (ur_rtde, …).
    Ursim {
        /// Robot model (ur3, ur5, ur10: CB3 at 125 Hz; ur3e … ur30: e-Series at 500 Hz).
        #[arg(long, value_parser = args::model, default_value = "ur3")]
        model: Model,
        /// Address to serve on; one loopback address per simulated robot.
        #[arg(long, default_value = "127.0.0.2")]
        host: IpAddr,
        /// Stop after this many seconds (default: run until killed).
        #[arg(long)]
        seconds: Option<f64>,
    },
    #[command(
        about = "Compensate head motion live on the configured robot and tracker (simulated by default)",
        long_about = None
    )]
    Run(run_cmd::RunCmd),
    #[command(
        about = "The paper's two-robot experiment on the simulated world: `paper` and `mocomp` on the same trajectory",
        long_about = None
    )]
    Demo(Box<demo_cmd::DemoCmd>),
    #[command(
        about = "Store the coil's current pose relative to the head as the goal (written into the configuration)",
        long_about = None
    )]
    TeachGoal(teach_cmd::TeachCmd),
    /// The configuration every `--config` takes: print it with every key, or check it.
    Config(config_cmd::ConfigCmd),
    /// Talk to a UR controller (a real one, or `mocomp ursim`) with mocomp's client.
    Robot {
        #[command(subcommand)]
        command: RobotCommand,
    },
    /// Hand-eye and robot-world calibration: X = flange_from_marker, Y = base_from_tracker.
    Calibrate {
        #[command(subcommand)]
        command: CalibrateCommand,
    },
}

/// `mocomp track --frames DIR ...` or `mocomp track render ...`.
#[derive(Debug, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
struct TrackCli {
    #[command(subcommand)]
    command: Option<TrackCommand>,
    /// Directory of <name>_ir.png / <name>_depth.png pairs (16-bit; depth in mm, 0 = none).
    #[arg(long, value_name = "DIR", required = true)]
    frames: Option<PathBuf>,
    /// Camera intrinsics (TOML: width, height, fx, fy, cx, cy, k1, k2, k3, p1, p2, pixel_centre).
    #[arg(long, value_name = "FILE", required = true)]
    intrinsics: Option<PathBuf>,
    /// Marker geometry: .toml (points_mm), Atracsys .ini or NDI .rom.
    #[arg(long, value_name = "FILE", required = true)]
    geometry: Option<PathBuf>,
    /// Pipeline parameters (TOML; see README.md). Default: built-in values.
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// Write an overlay image per frame into this directory.
    #[arg(long, value_name = "DIR")]
    overlay: Option<PathBuf>,
    /// One JSON line per frame.
    #[arg(long)]
    json: bool,
}

#[derive(Debug, Subcommand)]
enum TrackCommand {
    /// Write synthetic frames of a marker (with ground truth) to a directory.
    Render {
        /// Output directory.
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Marker geometry (.toml, .ini, .rom).
        #[arg(long, value_name = "FILE")]
        geometry: PathBuf,
        /// Camera intrinsics (TOML). Default: a typical Kinect v2.
        #[arg(long, value_name = "FILE")]
        intrinsics: Option<PathBuf>,
        /// Number of frames.
        #[arg(long, default_value_t = 10)]
        count: usize,
        /// RNG seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Add sun spots, reflections and (every fifth frame) a hand.
        #[arg(long)]
        distractors: bool,
        /// Hide this fiducial (1-based) in every frame.
        #[arg(long, value_name = "K")]
        hide: Option<usize>,
    },
}

#[derive(Debug, Subcommand)]
enum CalibrateCommand {
    #[command(
        about = "Run the planned calibration poses on the configured robot, measure, solve and save (the arm moves)",
        long_about = None
    )]
    Collect(collect_cmd::CollectCmd),
    /// Solve for X and Y from a pairs file (CSV; see README.md for its columns).
    Solve {
        /// The pairs file.
        #[arg(long, value_name = "FILE")]
        pairs: PathBuf,
        /// Solver: li (the paper's linear method), shah, or refined (nonlinear, robust).
        #[arg(long, default_value = "refined", value_parser = ["li", "shah", "refined"])]
        method: String,
        /// Robot model, needed when the file has joint columns q1..q6.
        #[arg(long, value_parser = args::model)]
        robot: Option<Model>,
        /// The robot's own calibrated DH values (TOML), for joint columns.
        #[arg(long, value_name = "FILE", requires = "robot")]
        calibration: Option<PathBuf>,
        /// Expected tracker noise per axis: millimetres, degrees.
        #[arg(long, value_name = "MM,DEG", default_value = "0.1,0.1", value_parser = args::noise_pair)]
        tracker_noise: [f64; 2],
        /// Expected robot noise per axis: millimetres, degrees.
        #[arg(long, value_name = "MM,DEG", default_value = "0.03,0.01", value_parser = args::noise_pair)]
        robot_noise: [f64; 2],
        /// Leave outlier pairs out and solve again (they are reported either way).
        #[arg(long)]
        reject_outliers: bool,
        /// Write X and Y with the residual report to this TOML file.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Propose robot poses for a calibration run around a centre flange pose.
    Plan {
        /// Robot model.
        #[arg(long, value_parser = args::model)]
        robot: Model,
        /// Centre flange pose as a UR pose vector (m, rotation vector).
        #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = args::six, allow_hyphen_values = true)]
        center: [f64; 6],
        /// Number of poses.
        #[arg(long, default_value_t = 20)]
        count: usize,
        /// Current joints (the run starts here and stays on their branch). Default: the IK
        /// solution of the centre nearest the zero configuration.
        #[arg(long, value_name = "Q1,...,Q6", value_parser = args::six, allow_hyphen_values = true)]
        current: Option<[f64; 6]>,
        /// Rough flange_from_marker (rotations turn about the marker's centre).
        #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = args::six, allow_hyphen_values = true)]
        marker: Option<[f64; 6]>,
        /// Rough base_from_tracker (tracker looking along +z): keeps the marker in view.
        #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = args::six, allow_hyphen_values = true)]
        tracker: Option<[f64; 6]>,
        /// Smallest rotation from the centre, degrees.
        #[arg(long, default_value_t = 15.0)]
        min_deg: f64,
        /// Largest rotation from the centre, degrees.
        #[arg(long, default_value_t = 40.0)]
        max_deg: f64,
        /// Shift the flange by up to this much per axis, metres.
        #[arg(long, default_value_t = 0.10)]
        spread_m: f64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Write a synthetic pairs file with known X and Y, for trying things out.
    Synth {
        /// Where to write it.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Number of pairs.
        #[arg(long, default_value_t = 20)]
        count: usize,
        /// RNG seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// True X = flange_from_marker (default: 12 cm out on the flange, turned).
        #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = args::six, allow_hyphen_values = true)]
        x: Option<[f64; 6]>,
        /// True Y = base_from_tracker (default: 1.5 m from the robot, facing it).
        #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = args::six, allow_hyphen_values = true)]
        y: Option<[f64; 6]>,
        /// Tracker noise per axis: millimetres, degrees.
        #[arg(long, value_name = "MM,DEG", default_value = "0.1,0.1", value_parser = args::noise_pair)]
        tracker_noise: [f64; 2],
        /// Robot noise per axis: millimetres, degrees.
        #[arg(long, value_name = "MM,DEG", default_value = "0.03,0.01", value_parser = args::noise_pair)]
        robot_noise: [f64; 2],
        /// Shift the flange by up to this much per axis, metres.
        #[arg(long, default_value_t = 0.20)]
        spread_m: f64,
    },
}

#[derive(Debug, Subcommand)]
enum RobotCommand {
    /// Connect, start the control program and print the state.
    State {
        /// Controller address.
        #[arg(long)]
        host: IpAddr,
        /// Start a simulated controller of this model at --host first.
        #[arg(long, value_parser = args::model)]
        ursim: Option<Model>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Stream a smooth joint trajectory with servoj at the controller rate; report the tracking
    /// error and the loop timing. Moves joints 1 and 6 by up to --amplitude: clear the space.
    Stream {
        /// Controller address.
        #[arg(long)]
        host: IpAddr,
        /// Robot model (for the TCP error).
        #[arg(long, value_parser = args::model)]
        model: Model,
        /// Start a simulated controller of --model at --host first.
        #[arg(long)]
        ursim: bool,
        /// Seconds to stream.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// Joint motion amplitude, radians.
        #[arg(long, default_value_t = 0.2)]
        amplitude: f64,
        /// Joint motion frequency, Hz.
        #[arg(long, default_value_t = 0.5)]
        frequency: f64,
        /// servoj lookahead time, seconds [0.03, 0.2].
        #[arg(long, default_value_t = 0.05)]
        lookahead: f64,
        /// servoj gain [100, 2000].
        #[arg(long, default_value_t = 1000.0)]
        gain: f64,
        /// Print one JSON object.
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
        Command::Run(c) => c.run(&mut out)?,
        Command::Config(c) => c.run(&mut out)?,
        Command::Ursim {
            model,
            host,
            seconds,
        } => {
            if seconds.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
                return Err(UsageError("--seconds: must be a positive number".into()).into());
            }
            robot_cmd::ursim(&mut out, model, host, seconds)?;
        }
        Command::Demo(c) => c.run(&mut out)?,
        Command::TeachGoal(c) => c.run(&mut out)?,
        Command::Robot { command } => robot(&mut out, command)?,
        Command::Calibrate { command } => calibrate(&mut out, command)?,
        Command::Track(t) => track(&mut out, t)?,
        Command::Listen {
            igtl,
            device,
            count,
            timeout,
            stt_tdata,
            json,
        } => {
            if !(timeout.is_finite() && timeout > 0.0) {
                return Err(UsageError(format!(
                    "--timeout {timeout}: must be a positive number of seconds"
                ))
                .into());
            }
            igtl_cmd::listen(
                &mut out,
                &igtl_cmd::ListenArgs {
                    addr: &igtl,
                    device: &device,
                    count,
                    timeout: std::time::Duration::from_secs_f64(timeout),
                    stt_tdata,
                    json,
                },
            )?;
        }
        Command::ServePoses {
            igtl_port,
            host,
            from,
            device,
            rate,
            count,
            header_version,
        } => {
            let path = PathBuf::from(&from);
            let feed = if from == "sim" {
                igtl_cmd::PoseFeed::Sim
            } else {
                igtl_cmd::PoseFeed::File(&path)
            };
            igtl_cmd::serve(
                &mut out,
                &igtl_cmd::ServeArgs {
                    host: &host,
                    port: igtl_port,
                    feed,
                    device: &device,
                    rate_hz: rate,
                    count,
                    header_version,
                },
            )?;
        }
    }
    out.flush()?;
    Ok(())
}

fn robot(out: &mut impl Write, command: RobotCommand) -> anyhow::Result<()> {
    match command {
        RobotCommand::State { host, ursim, json } => {
            let _sim = ursim.map(|m| robot_cmd::start_sim(m, host)).transpose()?;
            robot_cmd::state(out, host, json)
        }
        RobotCommand::Stream {
            host,
            model,
            ursim,
            seconds,
            amplitude,
            frequency,
            lookahead,
            gain,
            json,
        } => {
            for (name, v, lo, hi) in [
                ("--seconds", seconds, 0.1, 3600.0),
                ("--amplitude", amplitude, 0.0, 1.0),
                ("--frequency", frequency, 0.01, 5.0),
            ] {
                if !(v.is_finite() && v >= lo && v <= hi) {
                    return Err(UsageError(format!("{name} {v}: must be in [{lo}, {hi}]")).into());
                }
            }
            let _sim = ursim
                .then(|| robot_cmd::start_sim(model, host))
                .transpose()?;
            let a = robot_cmd::StreamArgs {
                seconds,
                amplitude,
                frequency,
                lookahead,
                gain,
            };
            robot_cmd::stream(out, model, host, a, json)
        }
    }
}

fn pose_arg(name: &str, v: &[f64; 6]) -> anyhow::Result<mocomp_geom::nalgebra::Isometry3<f64>> {
    mocomp_geom::iso_from_ur_pose(v).map_err(|e| UsageError(format!("{name}: {e}")).into())
}

fn track(out: &mut impl Write, t: TrackCli) -> anyhow::Result<()> {
    match t.command {
        Some(TrackCommand::Render {
            out: dir,
            geometry,
            intrinsics,
            count,
            seed,
            distractors,
            hide,
        }) => track_cmd::render_frames(
            out,
            &track_cmd::RenderArgs {
                out_dir: &dir,
                geometry: &geometry,
                intrinsics: intrinsics.as_deref(),
                count,
                seed,
                distractors,
                hide,
            },
        ),
        None => {
            let (Some(frames), Some(intrinsics), Some(geometry)) =
                (&t.frames, &t.intrinsics, &t.geometry)
            else {
                return Err(
                    UsageError("track needs --frames, --intrinsics and --geometry".into()).into(),
                );
            };
            track_cmd::track(
                out,
                &track_cmd::TrackArgs {
                    frames,
                    intrinsics,
                    geometry,
                    params: t.params.as_deref(),
                    overlay: t.overlay.as_deref(),
                    json: t.json,
                },
            )
        }
    }
}

fn calibrate(out: &mut dyn Write, command: CalibrateCommand) -> anyhow::Result<()> {
    use mocomp_calib::NoiseModel;
    let noise = |t: [f64; 2], r: [f64; 2]| NoiseModel::from_mm_deg(t[0], t[1], r[0], r[1]);
    match command {
        CalibrateCommand::Collect(c) => c.run(out),
        CalibrateCommand::Solve {
            pairs,
            method,
            robot,
            calibration,
            tracker_noise,
            robot_noise,
            reject_outliers,
            out: out_file,
            json,
        } => {
            let arm = match robot {
                Some(model) => Some(kin_cmd::arm(model, calibration.as_deref(), None)?),
                None => None,
            };
            let method = method
                .parse()
                .map_err(|e| UsageError(format!("--method: {e}")))?;
            calib_cmd::solve_cmd(
                out,
                &calib_cmd::SolveArgs {
                    pairs: &pairs,
                    arm,
                    method,
                    noise: noise(tracker_noise, robot_noise),
                    reject_outliers,
                    out_file: out_file.as_deref(),
                    json,
                },
            )
        }
        CalibrateCommand::Plan {
            robot,
            center,
            count,
            current,
            marker,
            tracker,
            min_deg,
            max_deg,
            spread_m,
            json,
        } => {
            if !(spread_m.is_finite() && spread_m >= 0.0) {
                return Err(UsageError(format!("--spread-m {spread_m}: must be ≥ 0")).into());
            }
            let args = calib_cmd::PlanArgs {
                arm: mocomp_kin::Arm::new(robot),
                center: pose_arg("--center", &center)?,
                count,
                current,
                marker: marker.map(|m| pose_arg("--marker", &m)).transpose()?,
                tracker: tracker.map(|t| pose_arg("--tracker", &t)).transpose()?,
                degrees: (min_deg, max_deg),
                spread_m,
                json,
            };
            calib_cmd::plan_cmd(out, &args)
        }
        CalibrateCommand::Synth {
            out: out_file,
            count,
            seed,
            x,
            y,
            tracker_noise,
            robot_noise,
            spread_m,
        } => {
            let mut options = mocomp_calib::synth::SynthOptions {
                count,
                seed,
                translation_spread_m: spread_m,
                noise: Some(noise(tracker_noise, robot_noise)),
                ..Default::default()
            };
            if let Some(x) = x {
                options.flange_from_marker = pose_arg("--x", &x)?;
            }
            if let Some(y) = y {
                options.base_from_tracker = pose_arg("--y", &y)?;
            }
            calib_cmd::synth_cmd(
                out,
                &calib_cmd::SynthArgs {
                    out_file: &out_file,
                    options,
                },
            )
        }
    }
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

/// A well-formed request the world refused (an unsafe goal, a robot that stopped): exit code 1.
#[derive(Debug)]
pub(crate) struct Refused(pub(crate) String);

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for Refused {}

/// Exit 2 for bad input (an argument, a file, a configuration value), 1 for everything that
/// fails at run time. Each error in the cause chain is asked in turn; the first that knows says.
/// An error nobody classifies is a run-time failure: calling a broken robot or a full disk "bad
/// input" would send the user to check arguments that are fine.
fn exit_code(err: &anyhow::Error) -> u8 {
    err.chain().find_map(classify).unwrap_or(EXIT_FAILURE)
}

/// Whether one error is bad input (2) or a run-time failure (1); `None`: not known here.
fn classify(e: &(dyn std::error::Error + 'static)) -> Option<u8> {
    use mocomp_app::experiment::ExperimentError;
    if let Some(e) = e.downcast_ref::<mocomp_app::AppError>() {
        // A failure's cause decides (a file not found is input; a lost robot is not).
        return match e {
            mocomp_app::AppError::Config(_) => Some(EXIT_USAGE),
            mocomp_app::AppError::Refused(_) => Some(EXIT_FAILURE),
            mocomp_app::AppError::Failed { .. } => None,
        };
    }
    if e.is::<UsageError>()
        || e.is::<mocomp_vision::VisionError>()
        || e.is::<mocomp_control::ParamError>()
        || e.is::<mocomp_geom::GeomError>()
        || e.is::<mocomp_igtl::name::NameError>()
        || e.is::<mocomp_control::GoalError>()
        || e.is::<mocomp_sim::MotionError>()
        || e.is::<mocomp_sim::trace::TraceError>()
        || e.is::<toml::de::Error>()
        || e.is::<serde_json::Error>()
    {
        return Some(EXIT_USAGE);
    }
    if e.is::<Refused>() || e.is::<igtl_cmd::NothingReceived>() || e.is::<mocomp_ursim::SimError>()
    {
        return Some(EXIT_FAILURE);
    }
    // A robot that is unreachable, refuses or faults is an outcome; a bad argument is not.
    if let Some(e) = e.downcast_ref::<mocomp_ur::UrError>() {
        return Some(match e {
            mocomp_ur::UrError::OutOfRange { .. } => EXIT_USAGE,
            _ => EXIT_FAILURE,
        });
    }
    // The experiment: its configuration is input; simulators, timeouts and calibration runs
    // are outcomes.
    if let Some(e) = e.downcast_ref::<ExperimentError>() {
        return Some(match e {
            ExperimentError::Config(_) | ExperimentError::Goal(_) | ExperimentError::Scene(_) => {
                EXIT_USAGE
            }
            ExperimentError::Io { .. }
            | ExperimentError::Timeout(_)
            | ExperimentError::Calibration { .. } => EXIT_FAILURE,
        });
    }
    // Calibration: bad or degenerate input is exit 2; a plan that cannot be met is exit 1.
    if let Some(e) = e.downcast_ref::<mocomp_calib::CalibError>() {
        return Some(match e {
            mocomp_calib::CalibError::PlanShort { .. } => EXIT_FAILURE,
            _ => EXIT_USAGE,
        });
    }
    // A pose that cannot be reached is an outcome; a malformed one is input.
    if let Some(e) = e.downcast_ref::<KinError>() {
        return Some(match e {
            KinError::Unreachable(_)
            | KinError::OutsideJointLimits { .. }
            | KinError::BranchUnavailable { .. }
            | KinError::NotConverged { .. } => EXIT_FAILURE,
            _ => EXIT_USAGE,
        });
    }
    // A file given that is not there or not readable as asked is input; any other I/O failure
    // (a full disk, a lost connection) happened at run time.
    if let Some(e) = e.downcast_ref::<std::io::Error>() {
        use std::io::ErrorKind;
        return Some(match e.kind() {
            ErrorKind::NotFound | ErrorKind::InvalidInput | ErrorKind::InvalidData => EXIT_USAGE,
            _ => EXIT_FAILURE,
        });
    }
    None
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
    use mocomp_app::experiment::ExperimentError;

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
        // A full disk, a simulator that timed out, an error nobody classified: run time.
        let full = std::io::Error::from(std::io::ErrorKind::StorageFull);
        assert_eq!(exit_code(&anyhow::Error::new(full)), EXIT_FAILURE);
        let timeout = ExperimentError::Timeout("the robots' states");
        assert_eq!(exit_code(&anyhow::Error::new(timeout)), EXIT_FAILURE);
        assert_eq!(exit_code(&anyhow::anyhow!("something odd")), EXIT_FAILURE);
        let cfg = ExperimentError::Config("seconds = -1".into());
        assert_eq!(exit_code(&anyhow::Error::new(cfg)), EXIT_USAGE);
    }
}
