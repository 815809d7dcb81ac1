//! `mocomp run --config FILE`: the live session ([`mocomp_app::live`]) until Ctrl-C or
//! `duration_s`; prints a status line each second, the events, and the summary.

use crate::dashboard::DashboardArgs;
use clap::Args;
use mocomp_app::frontend::{Both, Controls, Observer};
use mocomp_app::live::ros2::Ros2FrontEnd;
use mocomp_app::{AppError, config::Setup};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Compensate head motion live on the configured robot and tracker (simulated by default).
///
/// The configured robot (a UR, or a simulated one) keeps the coil at
/// its goal on the head seen by the configured tracker (OpenIGTLink, or simulated), until Ctrl-C
/// (which stops the robot) or `duration_s`. Prints a status line each second and a summary;
/// writes every cycle to a CSV log.
#[derive(Debug, Clone, Args)]
pub struct RunCmd {
    /// The configuration (TOML; `mocomp config print` shows every key, default and unit).
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Stop after this many seconds (overrides `duration_s`).
    #[arg(long, value_parser = crate::args::positive_number)]
    pub seconds: Option<f64>,
    /// Write every cycle to this CSV file (overrides `log_csv`).
    #[arg(long, value_name = "FILE")]
    pub log_csv: Option<String>,
    /// No status line or event lines while running (the summary is still printed).
    #[arg(long)]
    pub quiet: bool,
    /// Print the summary as one JSON object (figures, holds, protective stops, real time).
    #[arg(long)]
    pub json: bool,
    /// Be a ROS 2 node (sets `ros2.enabled`): publish joint states, TF, the coil's and the
    /// head's poses and diagnostics; serve /mocomp/hold and /mocomp/resume. The DDS domain is
    /// `ros2.domain_id`, else `ROS_DOMAIN_ID`.
    #[arg(long)]
    pub ros2: bool,
    /// Record the session to this MCAP file (overrides `record_mcap`): the ROS 2 topics and
    /// every cycle record, CDR with the ROS 2 profile (Foxglove, `ros2 bag`).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<String>,
    /// Serve the coil, its target and the head marker to 3D Slicer on this address
    /// (OpenIGTLink TRANSFORMs CoilToImage, TargetToImage, HeadMarkerToImage in the image's
    /// RAS; connect Slicer's OpenIGTLinkIF to it as a client).
    #[arg(long, value_name = "HOST:PORT")]
    pub slicer: Option<String>,
    /// The most updates a second sent to Slicer.
    #[arg(long, value_name = "HZ", default_value_t = 30.0, value_parser = crate::args::rate_hz)]
    pub slicer_rate_hz: f64,
    /// Start although the registration's estimated target error at the start goal is above
    /// `[head] max_tre_mm`, for this reason (appended to the registration file).
    #[arg(long, value_name = "WHY")]
    pub accept_registration: Option<String>,
    /// The operator's console.
    #[command(flatten)]
    pub dashboard: DashboardArgs,
}

impl RunCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        // The options that override the file, applied before it is checked, as its own values.
        let setup = Setup::load_with(&self.config, |file| {
            if let Some(s) = self.seconds {
                file.duration_s = s;
            }
            if self.log_csv.is_some() {
                file.log_csv.clone_from(&self.log_csv);
            }
            file.ros2.enabled |= self.ros2;
            if self.record.is_some() {
                file.record_mcap.clone_from(&self.record);
            }
        })?;
        for note in mocomp_app::live::start_notes(&setup, self.accept_registration.as_deref())? {
            eprintln!("{note}");
        }
        let controls = Controls::new();
        {
            let controls = Arc::clone(&controls);
            ctrlc::set_handler(move || controls.stop())?;
        }
        // With --json, standard output is the summary alone; what starts goes to standard error.
        let mut stderr = std::io::stderr();
        let progress: &mut dyn Write = if self.json { &mut stderr } else { out };
        // The front ends, attached from outside the loop: ROS 2 first (its DDS participant
        // takes a moment, before the robot connects), then the console.
        let mut ros2 = Ros2FrontEnd::start(&setup, &controls)?;
        let console = self.dashboard.start(&setup, &controls, progress)?;
        let mut observer: Box<dyn Observer> = if self.quiet {
            Box::new(mocomp_app::frontend::Silent)
        } else {
            Box::new(mocomp_app::live::logger::Lines(std::io::stderr()))
        };
        if let Some(c) = &console {
            observer = Box::new(Both(observer, c.observer()));
        }
        if let Some(o) = ros2.as_mut().and_then(Ros2FrontEnd::observer) {
            observer = Box::new(Both(observer, o));
        }
        if let Some(addr) = &self.slicer {
            let slicer =
                mocomp_app::live::slicer::Slicer::serve(&setup, addr, self.slicer_rate_hz)?;
            writeln!(
                progress,
                "3D Slicer: OpenIGTLink on {} ({}, image RAS)",
                slicer.local_addr(),
                mocomp_app::live::slicer::DEVICES.join(", ")
            )?;
            observer = Box::new(Both(observer, slicer));
        }
        let head = ros2.as_ref().and_then(Ros2FrontEnd::head_source);
        let log = setup.file.log_csv.as_deref().map(Path::new);
        let mut report = mocomp_app::live::run(&setup, log, &controls, observer, head, progress)?;
        // The loop has ended: the console's last status says so; it closes with this process.
        drop(console);
        if let Some(r) = ros2 {
            r.finish(&mut report);
        }
        if self.json {
            writeln!(out, "{}", serde_json::to_string(&report)?)?;
        } else {
            report.write_text(out, setup.file.log_csv.as_deref())?;
        }
        // The summary is out; what went wrong at the end still fails the run.
        if let Some(why) = report.failure(log) {
            return Err(AppError::Refused(why).into());
        }
        Ok(())
    }
}
