//! The demo's figures, each written as PNG and SVG:
//! - `d`: the paper's d(t) for both controllers on one time axis (its Fig. 11), linear and log;
//! - `errors`: translation (mm) and rotation (°) error of `E2_T_E1` over time;
//! - `head_speed`: the head's true speed (mm/s, °/s), the same for both controllers;
//! - `latency`: age of the newest tracker sample used, and the time from that sample to when the
//!   command takes effect (mocomp predicts over it; the paper's pipeline does not);
//! - `events`: each controller's mode over time (tracking, approaching, holding, faulted) with
//!   its safety events (holds, resumes, rejected outliers, approaches reached), and where the
//!   true coil was inside the head model.
//!
//! Text is set in DejaVu Sans compiled into the binary, so the figures look the same on every
//! machine and need no system fonts.

use mocomp_control::{Event, Mode};
use mocomp_experiment::experiment::{Controller, Record, Run};
use mocomp_geom::units::{m_to_mm, rad_to_deg};
use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Figure size in pixels (PNG) and user units (SVG).
const SIZE: (u32, u32) = (1100, 700);
/// The font family the figures use.
pub(crate) const FONT: &str = "sans-serif";

/// A figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The compiled-in font did not load.
    #[error("the plots' font (DejaVu Sans) did not load")]
    Font,
    /// Drawing failed.
    #[error("drawing {figure}: {detail}")]
    Draw {
        /// Which figure.
        figure: &'static str,
        /// Why.
        detail: String,
    },
    /// Writing a file failed.
    #[error("writing {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Encoding the PNG failed.
    #[error("encoding {path}: {detail}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// Why.
        detail: String,
    },
}

/// Registers the compiled-in font once.
pub(crate) fn font() -> Result<(), PlotError> {
    static LOADED: OnceLock<bool> = OnceLock::new();
    let ok = *LOADED.get_or_init(|| {
        plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_ok()
    });
    if ok { Ok(()) } else { Err(PlotError::Font) }
}

/// Each controller's colour: the paper's pipeline red, mocomp blue, the oracle green.
fn colour(c: Controller) -> RGBColor {
    match c {
        Controller::Paper => RGBColor(214, 39, 40),
        Controller::Mocomp => RGBColor(31, 119, 180),
        Controller::Oracle => RGBColor(44, 160, 44),
    }
}

/// A figure that draws itself on any backend.
trait Figure {
    /// Its file stem.
    fn name(&self) -> &'static str;
    /// Draws on `root` (already white).
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

/// Any drawing error as text.
pub(crate) fn e<E: std::fmt::Display>(err: E) -> String {
    err.to_string()
}

/// Writes `fig` as `dir/NAME.svg` and `dir/NAME.png`; returns both paths.
fn write<F: Figure>(fig: &F, dir: &Path) -> Result<[PathBuf; 2], PlotError> {
    font()?;
    let draw_err = |detail: String| PlotError::Draw {
        figure: fig.name(),
        detail,
    };
    // SVG.
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(e).map_err(draw_err)?;
        fig.draw(&root).map_err(draw_err)?;
        root.present().map_err(e).map_err(draw_err)?;
    }
    let svg_path = dir.join(format!("{}.svg", fig.name()));
    std::fs::write(&svg_path, svg).map_err(|source| PlotError::Write {
        path: svg_path.clone(),
        source,
    })?;
    // PNG: rendered into an RGB buffer, encoded with `image`.
    let mut rgb = vec![0u8; SIZE.0 as usize * SIZE.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(e).map_err(draw_err)?;
        fig.draw(&root).map_err(draw_err)?;
        root.present().map_err(e).map_err(draw_err)?;
    }
    let png_path = dir.join(format!("{}.png", fig.name()));
    image::save_buffer_with_format(
        &png_path,
        &rgb,
        SIZE.0,
        SIZE.1,
        image::ColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|err| PlotError::Encode {
        path: png_path.clone(),
        detail: err.to_string(),
    })?;
    Ok([svg_path, png_path])
}

/// Writes every figure into `dir`; returns the files written.
pub fn write_all(runs: &[Run], duration_s: f64, dir: &Path) -> Result<Vec<PathBuf>, PlotError> {
    let t = 0.0..duration_s.max(1e-3);
    let mut files = Vec::new();
    files.extend(write(&Deviation { runs, t: t.clone() }, dir)?);
    files.extend(write(
        &Panels {
            name: "errors",
            runs,
            t: t.clone(),
            panels: [
                ("translation error of E2_T_E1", "mm", |r| {
                    m_to_mm(r.translation_m)
                }),
                ("rotation error of E2_T_E1", "degrees", |r| {
                    rad_to_deg(r.rotation_rad)
                }),
            ],
        },
        dir,
    )?);
    files.extend(write(&HeadSpeed { runs, t: t.clone() }, dir)?);
    files.extend(write(
        &Panels {
            name: "latency",
            runs,
            t: t.clone(),
            panels: [
                ("age of the newest tracker sample used", "ms", |r| {
                    r.sample_age_s * 1e3
                }),
                (
                    "from the sample to the command's effect (mocomp predicts over it)",
                    "ms",
                    |r| r.horizon_s * 1e3,
                ),
            ],
        },
        dir,
    )?);
    files.extend(write(
        &Panels {
            name: "contact",
            runs,
            t: t.clone(),
            panels: [
                (
                    "force of the coil on the scalp (simulated contact: scalp over skull)",
                    "N",
                    |r| r.contact_force_n,
                ),
                (
                    "the coil's clearance from the head model (negative: pressing in)",
                    "mm",
                    |r| m_to_mm(r.coil_clearance_m),
                ),
            ],
        },
        dir,
    )?);
    if runs
        .iter()
        .any(|r| r.records.iter().any(|x| x.dose_pct.is_finite()))
    {
        files.extend(write(
            &Panels {
                name: "dose",
                runs,
                t: t.clone(),
                panels: [
                    (
                        "the field at the target along the planned direction, % of the planned",
                        "%",
                        |r| r.dose_pct,
                    ),
                    ("its error, |dose − planned|", "% of the planned", |r| {
                        (r.dose_pct - 100.0).abs()
                    }),
                ],
            },
            dir,
        )?);
    }
    files.extend(write(&Events { runs, t }, dir)?);
    Ok(files)
}

/// The finite points `(t, f(record))` of a run.
fn series(run: &Run, f: impl Fn(&Record) -> f64) -> Vec<(f64, f64)> {
    run.records
        .iter()
        .map(|r| (r.t, f(r)))
        .filter(|(_, y)| y.is_finite())
        .collect()
}

/// The largest value of `f` over all runs, with headroom (at least `floor`).
fn top(runs: &[Run], f: &dyn Fn(&Record) -> f64, floor: f64) -> f64 {
    let m = runs
        .iter()
        .flat_map(|r| r.records.iter().map(f))
        .filter(|y| y.is_finite())
        .fold(0.0, f64::max);
    (m * 1.08).max(floor)
}

/// A chart with time (s) on x and `y` on y, its caption, axes and grid drawn.
pub(crate) fn time_chart<'a, DB, Y>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    y_desc: &str,
    t: &Range<f64>,
    y: Y,
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y::CoordDescType>>, String>
where
    DB: DrawingBackend,
    Y: AsRangedCoord,
    Y::CoordDescType: ValueFormatter<Y::Value>,
    Y::Value: std::fmt::Debug + Clone,
{
    let mut chart = ChartBuilder::on(area)
        .caption(caption, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(t.clone(), y)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("time (s)")
        .y_desc(y_desc)
        .label_style((FONT, 14))
        .axis_desc_style((FONT, 15))
        .draw()
        .map_err(e)?;
    Ok(chart)
}

/// One panel of lines, one per run: `f` of each record against time.
fn line_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    caption: &str,
    y_desc: &str,
    runs: &[Run],
    t: &Range<f64>,
    f: &dyn Fn(&Record) -> f64,
) -> Result<(), String> {
    let y_max = top(runs, f, 1e-3);
    let mut chart = time_chart(area, caption, y_desc, t, 0.0..y_max)?;
    for run in runs {
        let c = colour(run.controller);
        chart
            .draw_series(LineSeries::new(series(run, f), c.stroke_width(1)))
            .map_err(e)?
            .label(run.controller.name())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], c.stroke_width(3)));
    }
    chart
        .configure_series_labels()
        .label_font((FONT, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(e)?;
    Ok(())
}

/// d(t), as the paper's Fig. 11, and on a log axis where mocomp's small deviations show.
struct Deviation<'a> {
    runs: &'a [Run],
    t: Range<f64>,
}

impl Figure for Deviation<'_> {
    fn name(&self) -> &'static str {
        "d"
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let (upper, lower) = root.split_vertically(SIZE.1 / 2);
        let f = |r: &Record| r.d;
        line_panel(
            &upper,
            "d(t) = ‖E2_T_E1,g − E2_T_E1‖_F  (as the paper's Fig. 11)",
            "d (translation in mm)",
            self.runs,
            &self.t,
            &f,
        )?;
        // Log axis: floor at 0.01 so a perfect tick stays on the chart.
        let y_max = top(self.runs, &f, 1.0);
        let mut chart = time_chart(
            &lower,
            "d(t), log scale",
            "d",
            &self.t,
            (0.01..y_max).log_scale(),
        )?;
        for run in self.runs {
            let c = colour(run.controller);
            chart
                .draw_series(LineSeries::new(
                    series(run, |r| r.d.max(0.01)),
                    c.stroke_width(1),
                ))
                .map_err(e)?;
        }
        Ok(())
    }
}

/// The head's true speed (from the first run: the trajectory is the same for every controller).
struct HeadSpeed<'a> {
    runs: &'a [Run],
    t: Range<f64>,
}

impl Figure for HeadSpeed<'_> {
    fn name(&self) -> &'static str {
        "head_speed"
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let Some(run) = self.runs.first() else {
            return Ok(());
        };
        let (upper, lower) = root.split_vertically(SIZE.1 / 2);
        let grey = RGBColor(60, 60, 60);
        for (area, caption, unit, f) in [
            (
                &upper,
                "head speed, translation",
                "mm/s",
                &(|r: &Record| r.head_speed.0 * 1e3) as &dyn Fn(&Record) -> f64,
            ),
            (&lower, "head speed, rotation", "°/s", &|r: &Record| {
                r.head_speed.1.to_degrees()
            }),
        ] {
            let y_max = top(std::slice::from_ref(run), f, 1e-3);
            let mut chart = time_chart(area, caption, unit, &self.t, 0.0..y_max)?;
            chart
                .draw_series(LineSeries::new(series(run, f), grey.stroke_width(1)))
                .map_err(e)?;
        }
        Ok(())
    }
}

/// One panel of [`Panels`]: caption, unit, and the value of a record.
type Panel = (&'static str, &'static str, fn(&Record) -> f64);

/// Two panels of lines, one line per controller (errors, latency).
struct Panels<'a> {
    name: &'static str,
    runs: &'a [Run],
    t: Range<f64>,
    panels: [Panel; 2],
}

impl Figure for Panels<'_> {
    fn name(&self) -> &'static str {
        self.name
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let (upper, lower) = root.split_vertically(SIZE.1 / 2);
        for (area, (caption, unit, f)) in [&upper, &lower].into_iter().zip(self.panels) {
            line_panel(area, caption, unit, self.runs, &self.t, &f)?;
        }
        Ok(())
    }
}

/// The modes' colours, in the order of [`Mode::kind`] (tracking, approaching, holding, faulted,
/// retreating).
const MODE_COLOURS: [RGBColor; 5] = [
    RGBColor(44, 160, 44),
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
];

/// Counts of each kind of event in a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EventCounts {
    /// Holds (and faults) begun.
    pub holds: usize,
    /// Resumes.
    pub resumes: usize,
    /// Tracker samples rejected as outliers.
    pub outliers: usize,
    /// Planned approaches that reached the goal.
    pub reached: usize,
    /// Retreats begun.
    pub retreats: usize,
    /// Tracker dropouts coasted through.
    pub coasts: usize,
}

/// Counts each kind of event in a run.
pub fn event_counts(run: &Run) -> EventCounts {
    let mut n = EventCounts::default();
    for r in &run.records {
        match r.event {
            Some(Event::Hold(_)) => n.holds += 1,
            // A transit is a resume by a joint-space move.
            Some(Event::Resume | Event::Transit(_)) => n.resumes += 1,
            Some(Event::Outlier(..)) => n.outliers += 1,
            Some(Event::Reached) => n.reached += 1,
            Some(Event::Retreat(_)) => n.retreats += 1,
            Some(Event::Coasting(_)) => n.coasts += 1,
            // The lockstep experiment's robot never latches a fault; a re-arm is no motion.
            Some(Event::Rearmed) | None => {}
        }
    }
    n
}

/// Each controller's mode over time as a coloured band, its events as markers.
struct Events<'a> {
    runs: &'a [Run],
    t: Range<f64>,
}

impl Figure for Events<'_> {
    fn name(&self) -> &'static str {
        "events"
    }
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let rows = self.runs.len().max(1);
        let areas = root.split_evenly((rows, 1));
        for (run, area) in self.runs.iter().zip(&areas) {
            self.draw_run(run, area)?;
        }
        Ok(())
    }
}

type EventChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

impl Events<'_> {
    /// One controller's row: its modes as bands, its events as markers, a legend.
    fn draw_run<DB: DrawingBackend>(
        &self,
        run: &Run,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), String> {
        let EventCounts {
            holds,
            resumes,
            outliers,
            reached,
            retreats,
            coasts,
        } = event_counts(run);
        let period = match run.records.as_slice() {
            [a, b, ..] => b.t - a.t,
            _ => 0.0,
        };
        let caption = format!(
            "{}: mode and safety events ({holds} holds, {retreats} retreats, {resumes} resumes, {coasts} dropouts coasted, {outliers} outliers rejected, {reached} approaches reached)",
            run.controller.name()
        );
        let mut chart = ChartBuilder::on(area)
            .caption(caption, (FONT, 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(20)
            .build_cartesian_2d(self.t.clone(), 0.0..1.0)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("time (s)")
            .y_labels(0)
            .disable_y_mesh()
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 15))
            .draw()
            .map_err(e)?;
        self.draw_modes(&mut chart, run, period)?;
        draw_events(&mut chart, run)?;
        chart
            .configure_series_labels()
            .label_font((FONT, 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(e)?;
        Ok(())
    }

    /// Mode bands, and where the true coil was inside the head model.
    fn draw_modes<DB: DrawingBackend>(
        &self,
        chart: &mut EventChart<'_, DB>,
        run: &Run,
        period: f64,
    ) -> Result<(), String> {
        // Mode bands: one rectangle per stretch of one mode (ticks are one period long).
        let mut bands: Vec<(f64, f64, usize)> = Vec::new();
        let mut prev_t = self.t.start;
        for r in &run.records {
            let k = r.mode.kind();
            match bands.last_mut() {
                Some(b) if b.2 == k => b.1 = r.t,
                _ => bands.push((prev_t, r.t, k)),
            }
            prev_t = r.t;
        }
        for (k, (&name, &c)) in Mode::KINDS.iter().zip(&MODE_COLOURS).enumerate() {
            let mine: Vec<_> = bands
                .iter()
                .filter(|b| b.2 == k)
                .map(|&(t0, t1, _)| Rectangle::new([(t0, 0.35), (t1, 0.65)], c.mix(0.5).filled()))
                .collect();
            if mine.is_empty() {
                continue;
            }
            chart
                .draw_series(mine)
                .map_err(e)?
                .label(name)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 6), (x + 22, y + 6)], c.mix(0.5).filled())
                });
        }
        // Where the true coil was inside the head model: a red strip at the bottom.
        let inside: Vec<_> = run
            .records
            .iter()
            .filter(|r| r.coil_clearance_m < 0.0)
            .map(|r| Rectangle::new([(r.t - period, 0.02), (r.t, 0.1)], RED.filled()))
            .collect();
        if !inside.is_empty() {
            chart
                .draw_series(inside)
                .map_err(e)?
                .label("coil inside the head model")
                .legend(|(x, y)| Rectangle::new([(x, y - 6), (x + 22, y + 6)], RED.filled()));
        }
        Ok(())
    }
}

/// The events above the band: holds, resumes, outliers rejected, approaches reached.
fn draw_events<DB: DrawingBackend>(
    chart: &mut EventChart<'_, DB>,
    run: &Run,
) -> Result<(), String> {
    // Events above the band.
    let at = |want: fn(&Event) -> bool| -> Vec<f64> {
        run.records
            .iter()
            .filter(|r| r.event.as_ref().is_some_and(want))
            .map(|r| r.t)
            .collect()
    };
    let black = BLACK;
    let holds = at(|ev| matches!(ev, Event::Hold(_)));
    if !holds.is_empty() {
        chart
            .draw_series(
                holds
                    .iter()
                    .map(|&t| TriangleMarker::new((t, 0.8), 7, RGBColor(214, 39, 40).filled())),
            )
            .map_err(e)?
            .label("hold")
            .legend(|(x, y)| TriangleMarker::new((x + 11, y), 7, RGBColor(214, 39, 40).filled()));
    }
    let resumes = at(|ev| matches!(ev, Event::Resume));
    if !resumes.is_empty() {
        chart
            .draw_series(
                resumes
                    .iter()
                    .map(|&t| Circle::new((t, 0.8), 5, black.filled())),
            )
            .map_err(e)?
            .label("resume")
            .legend(move |(x, y)| Circle::new((x + 11, y), 5, black.filled()));
    }
    let outliers = at(|ev| matches!(ev, Event::Outlier(..)));
    if !outliers.is_empty() {
        chart
            .draw_series(
                outliers
                    .iter()
                    .map(|&t| Cross::new((t, 0.2), 6, black.stroke_width(2))),
            )
            .map_err(e)?
            .label("outlier rejected")
            .legend(move |(x, y)| Cross::new((x + 11, y), 6, black.stroke_width(2)));
    }
    let reached = at(|ev| matches!(ev, Event::Reached));
    if !reached.is_empty() {
        let blue = RGBColor(31, 119, 180);
        chart
            .draw_series(
                reached
                    .iter()
                    .map(|&t| Circle::new((t, 0.2), 5, blue.filled())),
            )
            .map_err(e)?
            .label("approach reached")
            .legend(move |(x, y)| Circle::new((x + 11, y), 5, blue.filled()));
    }
    Ok(())
}
