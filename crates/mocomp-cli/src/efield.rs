//! `mocomp efield`: the electric field of a coil model at points in a sphere, printed.

use anyhow::Result;
use clap::Args;
use mocomp_app::efield_calc::HeadSource;
use std::io::Write;
use std::path::PathBuf;

/// The electric field a TMS coil model induces at points inside a sphere (Heller and van
/// Hulsteyn: exact for the sphere, whatever its conductivity), for a coil pose as SimNIBS
/// gives one.
#[derive(Debug, Clone, Args)]
pub struct EfieldCmd {
    /// The coil model: a SimNIBS `.ccd` file (magnetic dipoles in the coil's frame).
    #[arg(long, value_name = "FILE.ccd")]
    coil: PathBuf,
    /// The coil's pose: SimNIBS's `matsimnibs`, 16 numbers row by row, translation in mm.
    #[arg(long, value_name = "M00,...,M33", value_parser = crate::args::numbers::<16>, allow_hyphen_values = true)]
    pose: [f64; 16],
    /// The sphere: its centre and radius, mm.
    #[arg(long, value_name = "X,Y,Z,R_MM", value_parser = crate::args::numbers::<4>, allow_hyphen_values = true, required_unless_present = "config", conflicts_with = "config")]
    sphere: Option<[f64; 4]>,
    /// Or: the sphere fitted to the scalp of this configuration's head under the coil (within
    /// 30 mm of the scalp point nearest the coil's centre), in the image's frame.
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// A point to compute the field at, mm (repeat for more).
    #[arg(long = "at", value_name = "X,Y,Z", value_parser = crate::args::three, allow_hyphen_values = true)]
    at: Vec<[f64; 3]>,
    /// Points from a CSV file: x,y,z in mm a line (a header line allowed).
    #[arg(long, value_name = "FILE.csv")]
    points: Option<PathBuf>,
    /// The coil current's rate of change, A/µs (without it: the file's dIdtmax).
    #[arg(long, value_name = "A_PER_US", allow_hyphen_values = true)]
    didt: Option<f64>,
    /// Print one JSON object: {"points": [{"at_mm": [x, y, z], "E_V_per_m": [ex, ey, ez]}]}.
    #[arg(long)]
    json: bool,
}

impl EfieldCmd {
    /// Runs it.
    pub fn run(self, out: &mut dyn Write) -> Result<()> {
        let report = mocomp_app::efield_calc::compute(&mocomp_app::efield_calc::Request {
            coil: &self.coil,
            matsimnibs: self.pose,
            head: match (&self.sphere, &self.config) {
                (Some(s), _) => HeadSource::Sphere(*s),
                (None, Some(c)) => HeadSource::Config(c),
                (None, None) => {
                    return Err(crate::UsageError("give --sphere or --config".into()).into());
                }
            },
            at_mm: self.at,
            points: self.points.as_deref(),
            didt_a_per_us: self.didt,
        })?;
        crate::print::report(out, &report, self.json)
    }
}
