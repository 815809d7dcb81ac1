//! `mocomp register`: patient-to-image registration with the calibrated pointer
//! ([`mocomp_app::register`]): the landmarks touched in turn, the scalp swept, the result written
//! with what it is worth; `mocomp register check`: whether the head marker moved on the head
//! since.

use clap::{Args, Subcommand};
use mocomp_app::config::Setup;
use mocomp_app::register::Streams;
use std::io::Write;
use std::path::PathBuf;
use std::time::Duration;

/// Register the patient's head marker to the image: touch the landmarks with the calibrated
/// pointer, each held still until taken, then sweep the scalp; writes the registration
/// (`[head] registration` reads it) with its FRE per landmark, the surface fit's RMS and the
/// estimated target error at the session's targets.
#[derive(Debug, Clone, Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct RegisterCmd {
    #[command(subcommand)]
    check: Option<RegisterSub>,
    #[command(flatten)]
    live: LiveArgs,
}

#[derive(Debug, Clone, Subcommand)]
enum RegisterSub {
    /// Touch one landmark again: has the head marker moved on the head since registration?
    Check(CheckArgs),
}

/// Where the configuration, the pointer and the streams are.
#[derive(Debug, Clone, Args)]
struct Common {
    /// The configuration: `[head] mesh` and `[head.landmarks]` (and, for `check`, `[head]
    /// registration`).
    #[arg(long, value_name = "FILE", required = true)]
    config: Option<PathBuf>,
    /// The pointer's calibration (`mocomp pointer calibrate`).
    #[arg(long, value_name = "FILE", default_value = "pointer.toml")]
    pointer: PathBuf,
    /// The OpenIGTLink server streaming the pointer and the head marker.
    #[arg(long, value_name = "HOST:PORT", required = true)]
    igtl: Option<String>,
    /// The head marker's device.
    #[arg(long, default_value = "HeadToTracker")]
    head_device: String,
    /// Give up when nothing arrives for this many seconds.
    #[arg(long, default_value_t = 30.0)]
    timeout: f64,
}

impl Common {
    fn open(&self) -> anyhow::Result<(Setup, Streams, mocomp_app::pointer::Pointer)> {
        crate::args::positive("--timeout", self.timeout)?;
        let config = self
            .config
            .as_ref()
            .ok_or_else(|| crate::UsageError("--config: needed".into()))?;
        let addr = self
            .igtl
            .clone()
            .ok_or_else(|| crate::UsageError("--igtl: needed".into()))?;
        let setup = Setup::load(config)?;
        let pointer = mocomp_app::pointer::load(&self.pointer)?;
        let streams = Streams {
            addr,
            head_device: self.head_device.clone(),
            timeout: Duration::from_secs_f64(self.timeout),
        };
        Ok((setup, streams, pointer))
    }
}

#[derive(Debug, Clone, Args)]
struct LiveArgs {
    #[command(flatten)]
    common: Common,
    /// The landmarks to touch, in order (each named in `[head.landmarks]`).
    #[arg(long, value_delimiter = ',', default_value = "nasion,lpa,rpa")]
    landmarks: Vec<String>,
    /// Points to sweep over the scalp (0: the landmarks alone).
    #[arg(long, default_value_t = 100)]
    sweep_points: usize,
    /// Where to write the registration.
    #[arg(long, value_name = "FILE", default_value = "registration.toml")]
    out: PathBuf,
    /// Print the result as one JSON object.
    #[arg(long)]
    json: bool,
    /// The operator's console: the registration waits for its Start, then shows each step.
    #[command(flatten)]
    dashboard: crate::dashboard::DashboardArgs,
}

#[derive(Debug, Clone, Args)]
struct CheckArgs {
    #[command(flatten)]
    common: Common,
    /// The landmark to touch.
    #[arg(long, default_value = "nasion")]
    landmark: String,
    /// Print the result as one JSON object.
    #[arg(long)]
    json: bool,
}

impl RegisterCmd {
    /// Runs it. `check` exits 1 when the marker moved.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        match self.check {
            Some(RegisterSub::Check(c)) => check(c, out),
            None => live(self.live, out),
        }
    }
}

fn live(a: LiveArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let (setup, streams, pointer) = a.common.open()?;
    let names: Vec<&str> = a.landmarks.iter().map(String::as_str).collect();
    let controls = mocomp_app::frontend::Controls::new();
    // With --json, standard output is the result alone: the console's line goes to stderr.
    let mut stderr = std::io::stderr();
    let progress: &mut dyn Write = if a.json { &mut stderr } else { out };
    let console = a.dashboard.start(&setup, &controls, progress)?;
    let mut page = crate::navigation_page::Page::new(console.as_ref(), "registration");
    if console.is_some() {
        page.wait_for_go(&controls)?;
    }
    let result = mocomp_app::register::register_live(
        &setup,
        &streams,
        &pointer,
        &names,
        a.sweep_points,
        &mut |s| eprintln!("{s}"),
        &mut |c| page.capture(c),
    );
    let r = match result {
        Ok(r) => r,
        Err(e) => {
            page.failed(&e.to_string());
            return Err(e.into());
        }
    };
    mocomp_app::registration_file::save(&a.out, &r.file)?;
    let rec = &r.file.registration;
    let targets = mocomp_app::registration_gate::target_errors(&setup, rec)?;
    page.registered(rec, &targets);
    if a.json {
        let json = serde_json::json!({
            "head_from_image": rec.head_from_image,
            "fre_mm": rec.fre_mm,
            "landmarks": rec.landmarks.iter().map(|(k, l)| (k.clone(), l.error_mm)).collect::<std::collections::BTreeMap<_, _>>(),
            "surface_rms_mm": rec.surface_rms_mm,
            "surface_points": rec.surface_points,
            "surface_too_far": r.too_far,
            "tre_mm": targets.iter().cloned().collect::<std::collections::BTreeMap<_, _>>(),
            "file": a.out.display().to_string(),
        });
        writeln!(out, "{json}")?;
        return Ok(());
    }
    writeln!(
        out,
        "registered: FRE {:.2} mm ({}); surface RMS {:.2} mm over {} points ({} too far left out)",
        rec.fre_mm,
        rec.landmarks
            .iter()
            .map(|(k, l)| format!("{k} {:.2}", l.error_mm))
            .collect::<Vec<_>>()
            .join(", "),
        rec.surface_rms_mm,
        rec.surface_points,
        r.too_far
    )?;
    for (name, tre) in &targets {
        writeln!(out, "  estimated target error at {name}: {tre:.1} mm")?;
    }
    writeln!(
        out,
        "written to {}; set [head] registration = \"{}\" to use it",
        a.out.display(),
        a.out.display()
    )?;
    Ok(())
}

fn check(c: CheckArgs, out: &mut dyn Write) -> anyhow::Result<()> {
    let (setup, streams, pointer) = c.common.open()?;
    let r = mocomp_app::register::check_live(&setup, &streams, &pointer, &c.landmark, &mut |s| {
        eprintln!("{s}")
    })?;
    if c.json {
        writeln!(
            out,
            "{}",
            serde_json::json!({"landmark": r.name, "moved_mm": r.moved_m * 1e3, "limit_mm": r.limit_m * 1e3, "moved": r.moved})
        )?;
    } else {
        writeln!(
            out,
            "{}: {:.2} mm from where it was touched at registration{}",
            r.name,
            r.moved_m * 1e3,
            if r.moved { "" } else { ": the marker holds" }
        )?;
    }
    if r.moved {
        return Err(mocomp_app::AppError::Refused(format!(
            "the head marker moved on the head ({:.1} mm at the {}, more than a touch's {:.1} mm): register again",
            r.moved_m * 1e3,
            r.name,
            r.limit_m * 1e3
        ))
        .into());
    }
    Ok(())
}
