//! `mocomp targets list|add|delete|grid --file FILE`: the session's named targets
//! ([`mocomp_app::navigation::targets`]).

use crate::UsageError;
use anyhow::Context;
use clap::{Args, Subcommand};
use mocomp_app::config::Setup;
use mocomp_app::navigation::{DoseTargeting, TargetSpec};
use mocomp_session::GridParams;
use std::io::Write;
use std::path::PathBuf;

/// A session's targets.
#[derive(Debug, Clone, Args)]
pub struct TargetsCmd {
    /// The targets file (TOML; created when a target is first written).
    #[arg(
        long,
        value_name = "FILE",
        global = true,
        default_value = "session-targets.toml"
    )]
    file: PathBuf,
    #[command(subcommand)]
    command: TargetsCommand,
}

#[derive(Debug, Clone, Subcommand)]
enum TargetsCommand {
    /// Print the targets: name, position (mm) and approach axis in the head marker's frame, when
    /// taught, note.
    List {
        /// One JSON object per target instead.
        #[arg(long)]
        json: bool,
    },
    /// Place a target from the image on the scalp of the configuration's `[head] mesh`: a brain
    /// point (`--image`, RAS mm), an MNI coordinate (`--mni`, through `--mni-affine`), or a
    /// 10-10 position (`--eeg F3`, from `[head.landmarks]`). The coil goes over the scalp point
    /// nearest it, its face `--standoff-mm` off, +z into the head, its handle (+y) posterior
    /// unless `--handle` says otherwise, in the head marker's frame through `[head]
    /// head_from_image`; checked as the loop checks its goal.
    Add(Box<AddCmd>),
    /// Import targets from another navigator's file: SimNIBS `matsimnibs` text, a Localite
    /// InstrumentMarker/TriggerMarker XML, a Brainsight NIfTI:Aligned export (coil poses, kept
    /// as planned), or 3D Slicer markups (points, each placed as `targets add --image` does);
    /// each checked on this patient's scalp.
    Import(ImportCmd),
    /// Delete a target.
    Delete {
        /// Its name.
        name: String,
    },
    /// Add a grid of targets around one, on the head model's surface, each coil along the
    /// surface normal, named NAME-r<row>c<col>.
    Grid {
        /// The target at the grid's centre.
        name: String,
        /// The configuration whose `[head]` model the grid lies on.
        #[arg(long, value_name = "FILE")]
        config: PathBuf,
        /// Distance between neighbours, mm.
        #[arg(long, value_name = "MM", default_value_t = 10.0)]
        spacing_mm: f64,
        /// Rows (along the target's y).
        #[arg(long, default_value_t = 3)]
        rows: usize,
        /// Columns (along the target's x).
        #[arg(long, default_value_t = 3)]
        cols: usize,
    },
}

/// `targets add`.
#[derive(Debug, Clone, Args)]
#[command(group = clap::ArgGroup::new("where").required(true).args(["image", "mni", "eeg"]))]
struct AddCmd {
    /// Its name.
    name: String,
    /// The configuration whose `[head]` holds the scan, its landmarks and head_from_image.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// A point in the image, RAS, mm.
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::args::three, allow_hyphen_values = true)]
    image: Option<[f64; 3]>,
    /// An MNI coordinate, mm.
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::args::three, allow_hyphen_values = true)]
    mni: Option<[f64; 3]>,
    /// The affine from MNI to the image (4 rows of 4 numbers, mm; from your normalisation);
    /// without it the image is taken to be in MNI space.
    #[arg(long, value_name = "FILE", requires = "mni")]
    mni_affine: Option<PathBuf>,
    /// A 10-10 position on the scalp (F3, C3, …).
    #[arg(long, value_name = "NAME")]
    eeg: Option<String>,
    /// The coil face's distance from the scalp, mm (SimNIBS's default).
    #[arg(long, value_name = "MM", default_value_t = 4.0)]
    standoff_mm: f64,
    /// The direction the handle points along, image RAS (projected onto the scalp there).
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::args::three, allow_hyphen_values = true, default_value = "0,-1,0")]
    handle: [f64; 3],
    /// Then turned about the coil's axis, degrees (counter-clockwise seen from outside).
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    handle_turn_deg: f64,
    /// Free text.
    #[arg(long, default_value = "")]
    note: String,
    /// Place and turn the coil for the largest dose at the target (the field of `[coil]
    /// model`), within `--dose-radius-mm` of the nearest scalp point.
    #[arg(long)]
    optimize_dose: bool,
    /// How far the search may move the coil's centre, mm.
    #[arg(
        long,
        value_name = "MM",
        default_value_t = 10.0,
        requires = "optimize_dose"
    )]
    dose_radius_mm: f64,
    /// The dose is the field along this direction (image RAS; a gyral wall's normal), not |E|.
    #[arg(long, value_name = "X,Y,Z", value_parser = crate::args::three, allow_hyphen_values = true, requires = "optimize_dose")]
    dose_direction: Option<[f64; 3]>,
    /// Write every place and turn the search evaluated to this CSV (its map).
    #[arg(long, value_name = "FILE", requires = "optimize_dose")]
    dose_map: Option<PathBuf>,
}

/// `targets import`.
#[derive(Debug, Clone, Args)]
struct ImportCmd {
    /// The navigator's file.
    #[arg(value_name = "FILE")]
    from_file: PathBuf,
    /// Which navigator wrote it.
    #[arg(long, value_name = "simnibs|localite|brainsight|slicer")]
    from: mocomp_app::navigation::target_import::Source,
    /// The configuration whose `[head]` holds the scan and head_from_image.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// Slicer points: the coil face's distance from the scalp, mm.
    #[arg(long, value_name = "MM", default_value_t = 4.0)]
    standoff_mm: f64,
}

impl ImportCmd {
    fn run(self, file: &std::path::Path, out: &mut dyn Write) -> anyhow::Result<()> {
        let setup = Setup::load(&self.config)?;
        let text = std::fs::read_to_string(&self.from_file)
            .with_context(|| format!("reading {}", self.from_file.display()))?;
        let found = mocomp_app::navigation::target_import::import(
            &setup,
            self.from,
            &self.from_file.display().to_string(),
            &text,
            standoff_m(self.standoff_mm)?,
            &mocomp_nav::Handle::default(),
        )?;
        mocomp_app::navigation::targets::teach_all(file, &found)?;
        for t in &found {
            writeln!(out, "{}", t.line())?;
        }
        let n = found.len();
        writeln!(out, "imported {n} targets into {}", file.display())?;
        Ok(())
    }
}

/// `--standoff-mm`, checked, in metres.
fn standoff_m(mm: f64) -> Result<f64, UsageError> {
    if !(mm.is_finite() && mm >= 0.0) {
        return Err(UsageError(format!(
            "--standoff-mm {mm}: must be a distance, 0 or more"
        )));
    }
    Ok(mm * 1e-3)
}

impl AddCmd {
    fn spec(&self) -> anyhow::Result<TargetSpec> {
        use mocomp_app::files::affine::read_affine;
        Ok(match (self.image, self.mni, &self.eeg) {
            (Some(p), _, _) => TargetSpec::Image(p),
            (_, Some(p), _) => TargetSpec::Mni(
                p,
                match &self.mni_affine {
                    Some(f) => Some((read_affine(f)?, f.display().to_string())),
                    None => None,
                },
            ),
            (_, _, Some(name)) => TargetSpec::Eeg(name.clone()),
            _ => return Err(UsageError("--image, --mni or --eeg".into()).into()),
        })
    }

    fn run(self, file: &std::path::Path, out: &mut dyn Write) -> anyhow::Result<()> {
        let setup = Setup::load(&self.config)?;
        let spec = self.spec()?;
        let standoff_m = standoff_m(self.standoff_mm)?;
        if !self.handle_turn_deg.is_finite() {
            return Err(UsageError("--handle-turn-deg: not a finite number".into()).into());
        }
        let handle = mocomp_nav::Handle {
            toward: self.handle.into(),
            turn_rad: self.handle_turn_deg.to_radians(),
        };
        let dose = self.optimize_dose.then_some(DoseTargeting {
            radius_m: self.dose_radius_mm * 1e-3,
            direction: self.dose_direction,
        });
        let placed = mocomp_app::navigation::place_target(
            &setup,
            &self.name,
            &spec,
            standoff_m,
            &handle,
            &self.note,
            dose.as_ref(),
        )?;
        if let (Some(map), Some(path)) = (&placed.dose, &self.dose_map) {
            mocomp_app::navigation::write_dose_map(path, map)?;
        }
        mocomp_app::navigation::targets::teach_all(file, std::slice::from_ref(&placed.target))?;
        write!(out, "{placed}")?;
        let reach = mocomp_app::navigation::target_report::reach_lines(
            &setup,
            &placed.target,
            &self.config,
        )?;
        for line in reach {
            writeln!(out, "{line}")?;
        }
        Ok(())
    }
}

impl TargetsCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> anyhow::Result<()> {
        match self.command {
            TargetsCommand::List { json } => {
                for t in &mocomp_app::navigation::targets::load(&self.file)?.targets {
                    writeln!(out, "{}", if json { t.json() } else { t.line() })?;
                }
            }
            TargetsCommand::Add(add) => return add.run(&self.file, out),
            TargetsCommand::Import(import) => return import.run(&self.file, out),
            TargetsCommand::Delete { name } => {
                mocomp_app::navigation::targets::delete(&self.file, &name)?;
                writeln!(out, "deleted {name}")?;
            }
            TargetsCommand::Grid {
                name,
                config,
                spacing_mm,
                rows,
                cols,
            } => {
                let setup = Setup::load(&config)?;
                let p = GridParams {
                    spacing_m: spacing_mm * 1e-3,
                    rows,
                    cols,
                };
                let names =
                    mocomp_app::navigation::targets::add_grid(&self.file, &setup, &name, &p)?;
                writeln!(out, "added {} targets: {}", names.len(), names.join(", "))?;
            }
        }
        Ok(())
    }
}
