//! A TMS session's report: one self-contained HTML page (the figures inline as SVG, no script,
//! no file beside it) with what a lab files with the session: when it ran, the registration and
//! how good it was, each target's pulses and errors, the figures of every pulse's error and
//! distance to the scalp over the session, and every pulse in a table.

use crate::plots::{PlotError, e, font, time_chart};
use mocomp_session::{Pulse, iso8601};
use plotters::coord::Shift;
use plotters::prelude::*;
use quick_xml::escape::escape;
use std::fmt::Write;

/// The registration, as the report shows it.
#[derive(Debug, Clone, PartialEq)]
pub struct RegistrationView {
    /// Its file.
    pub file: String,
    /// When it was made.
    pub registered_at: String,
    /// The landmarks' RMS error, mm.
    pub fre_mm: f64,
    /// Each landmark's error, mm.
    pub landmarks: Vec<(String, f64)>,
    /// The swept points' RMS distance from the scalp (mm) and how many (0: none swept).
    pub surface: (f64, usize),
}

/// What the report is made of.
#[derive(Debug, Clone)]
pub struct SessionReport<'a> {
    /// The session's configuration file.
    pub config: &'a str,
    /// The pulse log.
    pub log: &'a str,
    /// The pulses.
    pub pulses: &'a [Pulse],
    /// The registration, when the session had one.
    pub registration: Option<RegistrationView>,
    /// The gate's tolerances: position (mm) and angle (°).
    pub gate: (f64, f64),
    /// mocomp's version.
    pub version: &'a str,
}

/// The figures' size, user units.
const FIGURE: (u32, u32) = (900, 520);
/// The gate open (pulses on target) and shut.
const OPEN: RGBColor = RGBColor(31, 119, 180);
const SHUT: RGBColor = RGBColor(214, 39, 40);

fn h(s: &str) -> String {
    escape(s).into_owned()
}

fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "—".into()
    }
}

/// The median of the finite values, NaN for none.
fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn max(v: impl Iterator<Item = f64>) -> f64 {
    v.filter(|x| x.is_finite()).fold(f64::NAN, f64::max)
}

/// Each pulse's time from the session's first, s: UTC where the log has it, else loop time.
fn times(pulses: &[Pulse]) -> Vec<f64> {
    let t0 = pulses.first();
    pulses
        .iter()
        .map(|p| match (p.utc_unix_s, t0.and_then(|f| f.utc_unix_s)) {
            (Some(u), Some(u0)) => u - u0,
            _ => p.t_s - t0.map_or(0.0, |f| f.t_s),
        })
        .collect()
}

/// One panel: its caption, its unit, each pulse's value, and a limit drawn dashed.
type Panel<'a> = (&'a str, &'a str, fn(&Pulse) -> f64, Option<f64>);

/// Two panels over the session's time, a point per pulse (open-gate pulses blue, shut ones red).
struct PulseFigure<'a> {
    pulses: &'a [Pulse],
    t: Vec<f64>,
    panels: [Panel<'a>; 2],
}

impl PulseFigure<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        let end = self.t.iter().copied().fold(0.0, f64::max).max(1.0) * 1.02;
        let areas = root.split_evenly((2, 1));
        for (area, (caption, unit, f, limit)) in areas.iter().zip(&self.panels) {
            let values: Vec<f64> = self.pulses.iter().map(f).collect();
            let hi = values
                .iter()
                .copied()
                .chain(*limit)
                .filter(|v| v.is_finite())
                .fold(0.0, f64::max);
            let lo = values
                .iter()
                .copied()
                .filter(|v| v.is_finite())
                .fold(0.0, f64::min);
            // The axis is scaled to what it shows: the pulses and the limit, with headroom.
            let span = (hi - lo).max(1e-3);
            let y = (lo - 0.05 * span)..(hi + 0.1 * span);
            let mut chart = time_chart(area, caption, unit, &(0.0..end), y)?;
            if let Some(l) = limit {
                chart
                    .draw_series(DashedLineSeries::new(
                        [(0.0, *l), (end, *l)],
                        6,
                        4,
                        BLACK.mix(0.6).stroke_width(1),
                    ))
                    .map_err(e)?;
            }
            for (open, colour) in [(true, OPEN), (false, SHUT)] {
                let points = self
                    .t
                    .iter()
                    .zip(self.pulses)
                    .zip(&values)
                    .filter(|((_, p), v)| p.gate_open == open && v.is_finite())
                    .map(|((t, _), v)| Circle::new((*t, *v), 3, colour.filled()));
                chart.draw_series(points).map_err(e)?;
            }
        }
        Ok(())
    }
}

fn svg(fig: &PulseFigure<'_>) -> Result<String, PlotError> {
    font()?;
    let draw_err = |detail: String| PlotError::Draw {
        figure: "session",
        detail,
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, FIGURE).into_drawing_area();
        root.fill(&WHITE).map_err(e).map_err(draw_err)?;
        fig.draw(&root).map_err(draw_err)?;
        root.present().map_err(e).map_err(draw_err)?;
    }
    Ok(svg)
}

/// The report's HTML.
pub fn html(r: &SessionReport<'_>) -> Result<String, PlotError> {
    let (errors, scalp) = figures(r)?;
    let mut o = String::new();
    facts(&mut o, r);
    registration(&mut o, r);
    targets(&mut o, r.pulses);
    o.push_str("<h2>Figures</h2>\n");
    for (id, fig) in [("errors", &errors), ("scalp", &scalp)] {
        let _ = writeln!(o, "<figure id=\"figure-{id}\">{fig}</figure>");
    }
    pulses(&mut o, r.pulses);
    o.push_str("</body>\n</html>\n");
    Ok(o)
}

/// The two figures: each pulse's errors against the gate, and its scalp distance and output.
fn figures(r: &SessionReport<'_>) -> Result<(String, String), PlotError> {
    let p = r.pulses;
    let t = times(p);
    let errors = svg(&PulseFigure {
        pulses: p,
        t: t.clone(),
        panels: [
            (
                "each pulse's position error (the gate's tolerance dashed; red: gate shut)",
                "mm",
                |p| p.position_error_m * 1e3,
                Some(r.gate.0),
            ),
            (
                "each pulse's angle error",
                "degrees",
                |p| p.angle_error_rad.to_degrees(),
                Some(r.gate.1),
            ),
        ],
    })?;
    let scalp = svg(&PulseFigure {
        pulses: p,
        t: t.clone(),
        panels: [
            (
                "the coil's distance to the scalp at each pulse",
                "mm",
                |p| p.scalp_distance_m * 1e3,
                None,
            ),
            (
                "the stimulator's output at each pulse",
                "% of maximum",
                |p| p.output_pct.unwrap_or(f64::NAN),
                None,
            ),
        ],
    })?;
    Ok((errors, scalp))
}

/// The head of the page and the session's facts.
fn facts(o: &mut String, r: &SessionReport<'_>) {
    let p = r.pulses;
    let first = p.first().and_then(|x| x.utc_unix_s).map(iso8601);
    let last = p.last().and_then(|x| x.utc_unix_s).map(iso8601);
    let shut = p.iter().filter(|x| !x.gate_open).count();
    // Writing into a String cannot fail.
    let _ = write!(
        *o,
        "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <title>mocomp session report</title>\n<style>\n\
         body{{font-family:sans-serif;margin:2em;max-width:1000px;color:#222}}\
         table{{border-collapse:collapse;margin:.5em 0 1.5em}}\
         td,th{{border:1px solid #ccc;padding:.2em .5em;text-align:right;white-space:nowrap}}\
         th{{background:#f3f3f3}}td.l,th.l{{text-align:left}}tr.shut td{{color:#b22}}\
         figure{{margin:1em 0}}\n</style>\n</head>\n<body>\n\
         <h1>TMS session</h1>\n<table class=\"facts\">\n\
         <tr><th class=\"l\">configuration</th><td class=\"l\">{}</td></tr>\n\
         <tr><th class=\"l\">pulse log</th><td class=\"l\">{}</td></tr>\n\
         <tr><th class=\"l\">first pulse (UTC)</th><td class=\"l\">{}</td></tr>\n\
         <tr><th class=\"l\">last pulse (UTC)</th><td class=\"l\">{}</td></tr>\n\
         <tr><th class=\"l\">pulses</th><td class=\"l\" id=\"pulse-count\">{}</td></tr>\n\
         <tr><th class=\"l\">of them with the gate shut</th><td class=\"l\" id=\"shut-count\">{}</td></tr>\n\
         <tr><th class=\"l\">the gate's tolerances</th><td class=\"l\">{} mm, {}°</td></tr>\n\
         <tr><th class=\"l\">written by</th><td class=\"l\">mocomp {}</td></tr>\n</table>\n",
        h(r.config),
        h(r.log),
        first.as_deref().unwrap_or("—"),
        last.as_deref().unwrap_or("—"),
        p.len(),
        shut,
        num(r.gate.0, 2),
        num(r.gate.1, 2),
        h(r.version),
    );
}

/// The registration the session ran with, landmark by landmark, or why there was none.
fn registration(o: &mut String, r: &SessionReport<'_>) {
    o.push_str("<h2>Registration</h2>\n");
    match &r.registration {
        Some(g) => {
            let _ = write!(
                *o,
                "<p>{} ({}): landmarks' RMS error {} mm; the scalp swept at {} points, {} mm RMS \
                 from the image's scalp.</p>\n<table id=\"registration\"><tr><th class=\"l\">\
                 landmark</th><th>error (mm)</th></tr>\n",
                h(&g.file),
                h(&g.registered_at),
                num(g.fre_mm, 2),
                g.surface.1,
                num(g.surface.0, 2),
            );
            for (n, err) in &g.landmarks {
                let _ = writeln!(
                    *o,
                    "<tr><td class=\"l\">{}</td><td>{}</td></tr>",
                    h(n),
                    num(*err, 2)
                );
            }
            o.push_str("</table>\n");
        }
        None => o.push_str(
            "<p>None: the session's targets and poses are in the head marker's frame (taught on \
             the head, or the configured head_from_image).</p>\n",
        ),
    }
}

/// Per target: its pulses, the gate's refusals, the errors' median and largest.
fn targets(o: &mut String, p: &[Pulse]) {
    o.push_str(
        "<h2>Targets</h2>\n<table id=\"targets\"><tr><th class=\"l\">target</th><th>pulses</th>\
         <th>gate shut</th><th>position error median / max (mm)</th><th>angle error median / \
         max (°)</th><th>scalp distance median (mm)</th></tr>\n",
    );
    let mut names: Vec<&str> = Vec::new();
    for x in p {
        if !names.contains(&x.target.as_str()) {
            names.push(&x.target);
        }
    }
    for n in names {
        let of: Vec<&Pulse> = p.iter().filter(|x| x.target == n).collect();
        let pos = || of.iter().map(|x| x.position_error_m * 1e3);
        let ang = || of.iter().map(|x| x.angle_error_rad.to_degrees());
        let _ = writeln!(
            *o,
            "<tr><td class=\"l\">{}</td><td>{}</td><td>{}</td><td>{} / {}</td><td>{} / {}</td>\
             <td>{}</td></tr>",
            h(n),
            of.len(),
            of.iter().filter(|x| !x.gate_open).count(),
            num(median(pos().collect()), 2),
            num(max(pos()), 2),
            num(median(ang().collect()), 2),
            num(max(ang()), 2),
            num(
                median(of.iter().map(|x| x.scalp_distance_m * 1e3).collect()),
                2
            ),
        );
    }
    o.push_str("</table>\n");
}

/// Every pulse, a row each.
fn pulses(o: &mut String, p: &[Pulse]) {
    o.push_str(
        "<h2>Pulses</h2>\n<table id=\"pulses\"><tr><th>#</th><th class=\"l\">UTC</th>\
         <th class=\"l\">target</th><th>output (%)</th><th>position error (mm)</th>\
         <th>angle error (°)</th><th>scalp (mm)</th><th>dose (V/m)</th>\
         <th>dose (% planned)</th><th class=\"l\">gate</th>\
         <th class=\"l\">coil centre on the image (mm)</th></tr>\n",
    );
    for (k, x) in p.iter().enumerate() {
        let centre = x.image_from_coil.map_or_else(
            || "—".to_string(),
            |c| {
                let v = c.translation.vector * 1e3;
                format!("{:.1}, {:.1}, {:.1}", v.x, v.y, v.z)
            },
        );
        let gate = if x.gate_open {
            "open".to_string()
        } else {
            format!("shut: {}", x.why_shut)
        };
        let _ = writeln!(
            *o,
            "<tr class=\"pulse{}\"><td>{}</td><td class=\"l\">{}</td><td class=\"l\">{}</td>\
             <td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>\
             <td class=\"l\">{}</td><td class=\"l\">{}</td></tr>",
            if x.gate_open { "" } else { " shut" },
            k + 1,
            x.utc_unix_s.map(iso8601).as_deref().unwrap_or("—"),
            h(&x.target),
            x.output_pct.map_or_else(|| "—".into(), |v| num(v, 1)),
            num(x.position_error_m * 1e3, 2),
            num(x.angle_error_rad.to_degrees(), 2),
            num(x.scalp_distance_m * 1e3, 1),
            num(x.dose_v_per_m, 1),
            num(x.dose_pct, 1),
            h(&gate),
            centre,
        );
    }
    o.push_str("</table>\n");
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Isometry3;

    fn pulse(k: usize, target: &str, open: bool) -> Pulse {
        Pulse {
            t_s: 3.0 + 0.2 * k as f64,
            utc_unix_s: Some(1_796_000_000.0 + 0.2 * k as f64),
            stimulator_unix_s: None,
            target: target.into(),
            position_error_m: 0.0002 * (k % 5) as f64,
            angle_error_rad: 0.001,
            scalp_distance_m: 0.003,
            output_pct: Some(65.0),
            head_speed: (0.0, 0.0),
            gate_open: open,
            why_shut: if open {
                String::new()
            } else {
                "position error 2.40 mm".into()
            },
            image_from_coil: Some(Isometry3::translation(-0.04, 0.01, 0.09)),
            dose_v_per_m: 120.0 + k as f64,
            dose_pct: if k == 3 { f64::NAN } else { 99.0 },
        }
    }

    #[test]
    fn every_pulse_is_a_row_and_each_target_a_summary_with_two_figures() {
        let mut pulses: Vec<Pulse> = (0..12).map(|k| pulse(k, "C3", k != 7)).collect();
        pulses.extend((12..15).map(|k| pulse(k, "<C4 & more>", true)));
        let html = html(&SessionReport {
            config: "run.toml",
            log: "pulses.csv",
            pulses: &pulses,
            registration: Some(RegistrationView {
                file: "registration.toml".into(),
                registered_at: "2026-12-06T09:00:00Z".into(),
                fre_mm: 1.234,
                landmarks: vec![("nasion".into(), 0.9)],
                surface: (0.8, 120),
            }),
            gate: (2.0, 2.0),
            version: "0.1.0",
        })
        .unwrap();
        assert_eq!(html.matches("<tr class=\"pulse").count(), 15);
        assert_eq!(html.matches("<tr class=\"pulse shut\">").count(), 1);
        assert!(html.contains("id=\"pulse-count\">15<"), "{html}");
        assert!(html.contains("id=\"shut-count\">1<"), "{html}");
        // A target's name is text, never markup.
        assert!(html.contains("&lt;C4 &amp; more&gt;") && !html.contains("<C4"));
        assert_eq!(html.matches("<svg").count(), 2);
        assert!(html.contains("1.23 mm") && html.contains("registration.toml"));
        assert!(
            html.contains("2026-11-30T00:53:20Z"),
            "the first pulse's UTC"
        );
        // C3: 12 pulses, one shut; its errors 0, 0.2, …, 0.8 mm in turn: the median 0.30, the max 0.80.
        assert!(
            html.contains("<td class=\"l\">C3</td><td>12</td><td>1</td><td>0.30 / 0.80</td>"),
            "{html}"
        );
        // Each pulse's dose, V/m and % of the planned; none where the log has none.
        assert!(
            html.contains("<td>3.0</td><td>121.0</td><td>99.0</td><td class=\"l\">open</td>"),
            "{html}"
        );
        assert!(
            html.contains("<td>123.0</td><td>—</td><td class=\"l\">open</td>"),
            "{html}"
        );
    }

    #[test]
    fn a_session_without_pulses_or_registration_is_a_report_that_says_so() {
        let html = html(&SessionReport {
            config: "run.toml",
            log: "pulses.csv",
            pulses: &[],
            registration: None,
            gate: (2.0, 2.0),
            version: "0.1.0",
        })
        .unwrap();
        assert!(html.contains("id=\"pulse-count\">0<"));
        assert!(html.contains("<p>None: "));
        assert_eq!(html.matches("<tr class=\"pulse").count(), 0);
    }
}
