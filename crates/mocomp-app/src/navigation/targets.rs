//! The session's targets file ([`mocomp_session::targets`]) on disk: read (a missing file is a
//! session without targets yet), written whole through a temporary file and a rename so a crash
//! never leaves half a file, and the grid added from the configuration's head model.

use crate::config::Setup;
use crate::{AppError, Context};
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_session::{GridParams, Target, Targets, TargetsError};
use std::path::Path;

/// Reads the targets file at `path`; a file that does not exist yet reads as no targets.
pub fn load(path: &Path) -> Result<Targets, AppError> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Targets::default()),
        Err(e) => return Err(e).what(|| format!("reading the targets file {}", path.display())),
    };
    Targets::parse(&path.display().to_string(), &text).map_err(input)
}

/// Writes `targets` to `path`, whole.
pub fn save(path: &Path, targets: &Targets) -> Result<(), AppError> {
    crate::files::whole::write_whole(path, targets.to_toml().as_bytes(), "the targets file")
}

/// Now, as a target's `taught_at`: an HTTP date (UTC).
pub fn now() -> String {
    httpdate::fmt_http_date(std::time::SystemTime::now())
}

/// Writes `new` into the targets file at `file`, each replacing a target of its name.
pub fn teach_all(file: &Path, new: &[Target]) -> Result<(), AppError> {
    let mut targets = load(file)?;
    for t in new {
        targets.teach(t.clone()).map_err(input)?;
    }
    save(file, &targets)
}

/// Deletes the target `name` from the targets file at `file`.
pub fn delete(file: &Path, name: &str) -> Result<(), AppError> {
    let mut targets = load(file)?;
    targets.delete(name).map_err(input)?;
    save(file, &targets)
}

/// Adds the grid around the target `name` (on the head model of `setup`) to the targets file at
/// `file`; returns the new names.
pub fn add_grid(
    file: &Path,
    setup: &Setup,
    name: &str,
    p: &GridParams,
) -> Result<Vec<String>, AppError> {
    let mut targets = load(file)?;
    let names = targets
        .add_grid(&setup.file.head_model()?, name, p, &now())
        .map_err(input)?;
    save(file, &targets)?;
    Ok(names)
}

/// Everything wrong with targets is the user's input: a file, a name, a grid's parameters.
fn input(e: TargetsError) -> AppError {
    AppError::Config(e.to_string())
}

/// The session's targets file of `setup`: `[session] targets` (beside the configuration), else
/// `session-targets.toml` beside it.
pub fn session_file(setup: &Setup) -> std::path::PathBuf {
    setup.dir.join(
        setup
            .file
            .session
            .targets
            .as_deref()
            .unwrap_or("session-targets.toml"),
    )
}

/// Where the loop puts the coil for `target`: a target placed on the image is placed again
/// through the current `[head] head_from_image` (a new registration moves it with the image); a
/// taught one stays where it was taught on the marker.
pub fn head_from_coil(setup: &Setup, target: &Target) -> Isometry3<f64> {
    placed(&setup.file.head.head_from_image.iso(), target)
}

/// [`head_from_coil`] under `head_from_image`.
pub fn placed(head_from_image: &Isometry3<f64>, target: &Target) -> Isometry3<f64> {
    match target.image_from_coil {
        Some(p) => {
            head_from_image
                * Isometry3::new(
                    Vector3::new(p[0], p[1], p[2]),
                    Vector3::new(p[3], p[4], p[5]),
                )
        }
        None => target.pose(),
    }
}

/// The target `name` of the targets file `file` (else `[session] targets` of `config`,
/// relative to `dir`) as the goal under `config`'s `[head]`: for `mocomp demo --target`.
pub fn goal_named(
    config: &crate::config::Config,
    dir: &Path,
    name: &str,
    file: Option<&Path>,
) -> Result<Isometry3<f64>, AppError> {
    let path = match (file, &config.session.targets) {
        (Some(f), _) => f.to_path_buf(),
        (None, Some(f)) => dir.join(f),
        (None, None) => {
            return Err(AppError::Config(format!(
                "--target {name}: no targets file (--targets FILE, or [session] targets)"
            )));
        }
    };
    let targets = load(&path)?;
    let t = targets
        .get(name)
        .map_err(|e| AppError::Config(format!("--target {name}: {}: {e}", path.display())))?;
    Ok(placed(&config.head.head_from_image.iso(), t))
}
