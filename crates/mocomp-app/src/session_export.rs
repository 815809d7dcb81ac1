//! `mocomp session export` and `session report`: a session's pulse log (`[session] pulse_log`)
//! written as a NIBS-BIDS dataset ([`mocomp_navfiles::bids`]), a Localite trigger-marker file
//! ([`mocomp_navfiles::localite`]) or a report (one HTML page, [`mocomp_report::session`]). The configuration is read for where the log is, the image the
//! poses are in (its T1 goes into the dataset), its landmarks and registration, and the coil;
//! the head is not built (a scan is not segmented to export a log).

use crate::config::Config;
use crate::{AppError, Context};
use mocomp_navfiles::bids::{BidsSession, check_label, dataset};
use mocomp_session::{Pulse, read_log};
use std::path::{Path, PathBuf};

/// The configuration of a session, as the exports need it.
#[derive(Debug)]
pub struct ExportSource {
    /// The configuration, its registration and landmarks read.
    pub config: Config,
    /// Its directory (its relative paths are from there).
    pub dir: PathBuf,
    /// The pulse log read.
    pub log: PathBuf,
    /// Its pulses.
    pub pulses: Vec<Pulse>,
}

impl ExportSource {
    /// Reads the configuration at `path` and its pulse log (`log`, else `[session] pulse_log`).
    pub fn load(path: &Path, log: Option<&Path>) -> Result<Self, AppError> {
        let text = std::fs::read_to_string(path).what(|| format!("--config {}", path.display()))?;
        let mut config = Config::parse(&path.display().to_string(), &text)?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        config.load_registration(&dir)?;
        config.load_landmarks(&dir)?;
        let log = match (log, &config.session.pulse_log) {
            (Some(l), _) => l.to_path_buf(),
            (None, Some(l)) => dir.join(l),
            (None, None) => {
                return Err(AppError::Config(format!(
                    "{}: no session.pulse_log, and no --log FILE: no pulses to export",
                    path.display()
                )));
            }
        };
        let text =
            std::fs::read_to_string(&log).what(|| format!("the pulse log {}", log.display()))?;
        let pulses = read_log(&log.display().to_string(), &text)
            .map_err(|e| AppError::Config(e.to_string()))?;
        Ok(Self {
            config,
            dir,
            log,
            pulses,
        })
    }

    /// The T1 the poses are in: `t1` as given, else `[head] mesh` when it is a NIfTI.
    pub fn t1(&self, t1: Option<&Path>) -> Option<PathBuf> {
        match t1 {
            Some(t) => Some(t.to_path_buf()),
            None => self
                .config
                .head
                .mesh
                .as_ref()
                .filter(|m| crate::files::head::nifti_extension(m).is_some())
                .map(|m| self.dir.join(m)),
        }
    }
}

/// The labels and the T1 of a BIDS export.
#[derive(Debug, Clone)]
pub struct BidsOptions {
    /// `sub-` label.
    pub subject: String,
    /// `ses-` label.
    pub session: String,
    /// `task-` label.
    pub task: String,
    /// The T1 (default: [`ExportSource::t1`]).
    pub t1: Option<PathBuf>,
}

/// What an export wrote.
#[derive(Debug, Clone)]
pub struct Exported {
    /// Pulses written.
    pub pulses: usize,
    /// Of them, with the coil's pose.
    pub with_pose: usize,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Writes `source`'s pulses as a BIDS dataset in `dir` (made if need be; files of the same
/// names are replaced).
pub fn bids(source: &ExportSource, dir: &Path, o: &BidsOptions) -> Result<Exported, AppError> {
    for (option, label) in [
        ("--subject", &o.subject),
        ("--session", &o.session),
        ("--task", &o.task),
    ] {
        check_label(option, label).map_err(AppError::Config)?;
    }
    let t1 = source.t1(o.t1.as_deref());
    let t1_ext = match &t1 {
        Some(p) => Some(crate::files::head::nifti_extension(p).ok_or_else(|| {
            AppError::Config(format!(
                "--t1 {}: not a NIfTI (.nii or .nii.gz)",
                p.display()
            ))
        })?),
        None => None,
    };
    let head = &source.config.head;
    let session = BidsSession {
        subject: &o.subject,
        session: &o.session,
        task: &o.task,
        pulses: &source.pulses,
        t1: t1_ext,
        landmarks: head
            .landmarks
            .iter()
            .map(|(n, p)| (n.clone(), *p))
            .collect(),
        registration: source.config.loaded.registered.as_ref().map(|(_, r)| {
            (
                r.fre_mm,
                r.landmarks
                    .iter()
                    .map(|(n, l)| (n.clone(), l.error_mm))
                    .collect(),
            )
        }),
        coil_diameter_mm: 2e3 * source.config.coil.radius_m,
        version: env!("CARGO_PKG_VERSION"),
    };
    let mut written = Vec::new();
    for f in dataset(&session) {
        let path = dir.join(&f.path);
        write(&path, f.text.as_bytes())?;
        written.push(path);
    }
    if let (Some(from), Some(ext)) = (&t1, t1_ext) {
        let to = dir.join(format!(
            "sub-{s}/ses-{x}/anat/sub-{s}_ses-{x}_T1w.{ext}",
            s = o.subject,
            x = o.session
        ));
        if let Some(parent) = to.parent() {
            std::fs::create_dir_all(parent).what(|| format!("making {}", parent.display()))?;
        }
        std::fs::copy(from, &to)
            .what(|| format!("copying the T1 {} to {}", from.display(), to.display()))?;
        written.push(to);
    }
    Ok(exported(source, written))
}

/// Writes `source`'s pulses as a Localite trigger-marker file `file`.
pub fn localite(source: &ExportSource, file: &Path) -> Result<Exported, AppError> {
    let text = mocomp_navfiles::localite::trigger_markers(&source.pulses)
        .what(|| format!("writing {}", file.display()))?;
    write(file, text.as_bytes())?;
    Ok(exported(source, vec![file.to_path_buf()]))
}

/// Writes `source`'s report (HTML) to `file`.
pub fn report(source: &ExportSource, file: &Path, config: &Path) -> Result<Exported, AppError> {
    let registration = source.config.loaded.registered.as_ref().map(|(path, r)| {
        mocomp_report::session::RegistrationView {
            file: path.display().to_string(),
            registered_at: r.registered_at.clone(),
            fre_mm: r.fre_mm,
            landmarks: r
                .landmarks
                .iter()
                .map(|(n, l)| (n.clone(), l.error_mm))
                .collect(),
            surface: (r.surface_rms_mm, r.surface_points),
        }
    });
    let gate = &source.config.session.gate;
    let html = mocomp_report::session::html(&mocomp_report::session::SessionReport {
        config: &config.display().to_string(),
        log: &source.log.display().to_string(),
        pulses: &source.pulses,
        registration,
        gate: (
            gate.position_tolerance_m * 1e3,
            gate.angle_tolerance_rad.to_degrees(),
        ),
        version: env!("CARGO_PKG_VERSION"),
    })
    .what(|| format!("drawing the report {}", file.display()))?;
    write(file, html.as_bytes())?;
    Ok(exported(source, vec![file.to_path_buf()]))
}

fn exported(source: &ExportSource, files: Vec<PathBuf>) -> Exported {
    Exported {
        pulses: source.pulses.len(),
        with_pose: source
            .pulses
            .iter()
            .filter(|p| p.image_from_coil.is_some())
            .count(),
        files,
    }
}

/// Writes `bytes` to `path` whole, making its folder.
fn write(path: &Path, bytes: &[u8]) -> Result<(), AppError> {
    crate::files::whole::write_whole_making_folder(path, bytes, "the record's file")
}
