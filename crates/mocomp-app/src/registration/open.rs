//! Where `mocomp register` and `mocomp register check` take their poses from: a tracker's
//! OpenIGTLink stream with a pointer calibrated beforehand, or the rehearsal's simulated tracker
//! and operator, whose pointer is pivoted and calibrated first as a person would; and, in a
//! rehearsal, the registration's true error.

use crate::AppError;
use crate::config::Setup;
use crate::registration::pointer::Pointer;
use crate::registration::register::{Registered, Streams};
use crate::registration::rehearsal::{POINTER_DEVICE, Rehearsal, TIP_IN_MARKER_MM};
use mocomp_sim::operator::Ask;
use std::path::PathBuf;
use std::time::Duration;

/// The pointer file read when none is named and no rehearsal calibrates one.
pub const DEFAULT_POINTER_FILE: &str = "pointer.toml";

/// Poses a simulated pointer's pivot collects.
const PIVOT_POSES: usize = 300;

/// Where the poses come from, as the command line asked.
#[derive(Debug, Clone, PartialEq)]
pub struct Source {
    /// The rehearsal (with its operator's seed, if given) instead of a tracker.
    pub rehearse: Option<Option<u64>>,
    /// The tracker's OpenIGTLink server, HOST:PORT (needed without a rehearsal).
    pub igtl: Option<String>,
    /// The head marker's device name on that stream.
    pub head_device: String,
    /// The calibrated pointer's file (none: [`DEFAULT_POINTER_FILE`], or in a rehearsal the
    /// pointer calibrated there).
    pub pointer: Option<PathBuf>,
    /// How long to wait for a pose.
    pub timeout: Duration,
}

/// The streams open, the pointer known.
#[derive(Debug)]
pub struct Opened {
    /// The configuration.
    pub setup: Setup,
    /// The tracker's stream.
    pub streams: Streams,
    /// The calibrated pointer.
    pub pointer: Pointer,
    /// The rehearsal's world, when rehearsing.
    pub rehearsal: Option<Rehearsal>,
    /// What a rehearsal's pivot calibration found, to be said.
    pub said: Option<String>,
}

/// Opens `source` for `setup`.
pub fn open(setup: Setup, source: &Source) -> Result<Opened, AppError> {
    let (addr, head_device, rehearsal) = match source.rehearse {
        Some(seed) => {
            let r = Rehearsal::start(&setup, seed)?;
            (r.addr(), setup.file.tracker.device.clone(), Some(r))
        }
        None => {
            let addr = source
                .igtl
                .clone()
                .ok_or_else(|| AppError::Config("--igtl: needed".into()))?;
            (addr, source.head_device.clone(), None)
        }
    };
    let (pointer, said) = match (&source.pointer, &rehearsal) {
        (Some(p), _) => (crate::registration::pointer::load(p)?, None),
        (None, Some(r)) => {
            let (p, said) = simulated_pointer(r, source.timeout)?;
            (p, Some(said))
        }
        (None, None) => (
            crate::registration::pointer::load(std::path::Path::new(DEFAULT_POINTER_FILE))?,
            None,
        ),
    };
    let streams = Streams {
        addr,
        head_device,
        timeout: source.timeout,
    };
    Ok(Opened {
        setup,
        streams,
        pointer,
        rehearsal,
        said,
    })
}

/// The rehearsal's operator pivots the pointer; it is calibrated from those poses.
fn simulated_pointer(r: &Rehearsal, timeout: Duration) -> Result<(Pointer, String), AppError> {
    r.ask(Ask::Pivot);
    let (poses, invalid) = crate::registration::pointer::collect(
        &r.addr(),
        POINTER_DEVICE,
        PIVOT_POSES,
        timeout,
        &mut |_| {},
    )?;
    r.ask(Ask::Rest);
    let p = crate::registration::pointer::calibrate(POINTER_DEVICE, &poses, invalid)?;
    let [x, y, z] = p.tip_in_marker_mm;
    let said = format!(
        "simulated pointer calibrated: tip at ({x:.2}, {y:.2}, {z:.2}) mm, {:.2} mm RMS over {} \
         poses (truly at {:?} mm)",
        p.rms_mm, p.kept, TIP_IN_MARKER_MM
    );
    Ok((p, said))
}

impl Opened {
    /// Tells a rehearsal's operator what to do (nothing without one).
    pub fn ask(&self, a: Ask) {
        if let Some(r) = &self.rehearsal {
            r.ask(a);
        }
    }

    /// In a rehearsal, the registration's true error at each target (m).
    pub fn true_errors(&self, r: &Registered) -> Result<Option<Vec<(String, f64)>>, AppError> {
        let (Some(sim), Ok(reg)) = (&self.rehearsal, &r.outcome.registration) else {
            return Ok(None);
        };
        let targets = crate::registration::gate::targets(&self.setup, None)?;
        Ok(Some(crate::registration::rehearsal::true_errors(
            &targets,
            &reg.image_from_marker,
            &sim.image_from_marker(),
        )))
    }
}
