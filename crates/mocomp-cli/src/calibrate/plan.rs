//! `mocomp calibrate plan`: robot poses for a calibration run, printed.

use anyhow::{Context, Result};
use clap::Args;
use mocomp_calib::plan::{PlanOptions, TrackerView, plan, start_at_center, tour_time};
use mocomp_calib::summary::PlanReport;
use mocomp_kin::{Arm, Model};
use std::io::Write;

/// Propose robot poses for a calibration run around a centre flange pose.
#[derive(Debug, Clone, Args)]
pub struct PlanCmd {
    /// Robot model.
    #[arg(long, value_parser = crate::args::model)]
    robot: Model,
    /// Centre flange pose as a UR pose vector (m, rotation vector).
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = crate::args::six, allow_hyphen_values = true)]
    center: [f64; 6],
    /// Number of poses.
    #[arg(long, default_value_t = 20)]
    count: usize,
    /// Current joints (the run starts here and stays on their branch). Default: the IK
    /// solution of the centre nearest the zero configuration.
    #[arg(long, value_name = "Q1,...,Q6", value_parser = crate::args::six, allow_hyphen_values = true)]
    current: Option<[f64; 6]>,
    /// Rough flange_from_marker (rotations turn about the marker's centre).
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = crate::args::six, allow_hyphen_values = true)]
    marker: Option<[f64; 6]>,
    /// Rough base_from_tracker (tracker looking along +z): keeps the marker in view.
    #[arg(long, value_name = "X,Y,Z,RX,RY,RZ", value_parser = crate::args::six, allow_hyphen_values = true)]
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
}

impl PlanCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let args = &self;
        if !(args.spread_m.is_finite() && args.spread_m >= 0.0) {
            return Err(
                crate::UsageError(format!("--spread-m {}: must be ≥ 0", args.spread_m)).into(),
            );
        }
        let arm = Arm::new(args.robot);
        let center = crate::args::pose("--center", &args.center)?;
        let marker = args
            .marker
            .map(|m| crate::args::pose("--marker", &m))
            .transpose()?;
        let tracker = args
            .tracker
            .map(|t| crate::args::pose("--tracker", &t))
            .transpose()?;
        let current = match args.current {
            Some(q) => q,
            None => start_at_center(&arm, &center).context("--center")?,
        };
        let mut o = PlanOptions::new(args.count, center, current);
        o.rotation_range_rad = (args.min_deg.to_radians(), args.max_deg.to_radians());
        o.translation_spread_m = args.spread_m;
        if let Some(m) = marker {
            o.flange_from_marker = m;
        }
        o.tracker = tracker.map(TrackerView::typical);
        let poses = plan(&arm, &o)?;
        let tour = tour_time(&arm, &current, &poses);
        let r = PlanReport::new(arm.model(), current, &poses, tour, args.tracker.is_some());
        crate::print::report(out, &r, args.json)
    }
}
