//! The placement drawn for the person who places the chair: the robot's base from above, the arm's
//! reach, the head where it is configured and (after a search) where it should be, each with its
//! outline and the way its face looks, every target's coil marked reachable or not there, and the
//! move between the two places.

use crate::plots::{FONT, PlotError, e, font};
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use plotters::prelude::*;

/// One placement of the head.
#[derive(Debug, Clone)]
pub struct Place {
    /// The head in the robot's base frame.
    pub base_from_head: Isometry3<f64>,
    /// Each target: its name, its coil on the head (`head_from_coil`) and whether the arm reaches
    /// it here.
    pub targets: Vec<(String, Isometry3<f64>, bool)>,
}

/// What is drawn.
#[derive(Debug, Clone)]
pub struct PlacementView {
    /// The robot's model.
    pub robot: String,
    /// How far the arm reaches from its shoulder, m (a circle about the base).
    pub reach_m: f64,
    /// The head's outline in its own frame (points around it at the height of its widest part).
    pub outline: Vec<Point3<f64>>,
    /// Which way the face looks, in the head's frame (anterior).
    pub face: Vector3<f64>,
    /// The configured placement.
    pub configured: Place,
    /// The placement a search found.
    pub found: Option<Place>,
}

/// The figure's size, pixels.
const SIZE: (u32, u32) = (900, 900);
const CONFIGURED: RGBColor = RGBColor(120, 120, 120);
const FOUND: RGBColor = RGBColor(27, 138, 58);
const REFUSED: RGBColor = RGBColor(198, 40, 40);

/// The view from above, in mm of the base frame: every point drawn, to frame it.
fn extent(v: &PlacementView) -> (std::ops::Range<f64>, std::ops::Range<f64>) {
    let mut xs = vec![-v.reach_m, v.reach_m];
    let mut ys = vec![-v.reach_m, v.reach_m];
    for place in std::iter::once(&v.configured).chain(&v.found) {
        for p in &v.outline {
            let q = place.base_from_head * p;
            xs.push(q.x);
            ys.push(q.y);
        }
    }
    let lo = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min) * 1e3 - 60.0;
    let hi = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max) * 1e3 + 60.0;
    // Square, so that a circle is drawn round.
    let (cx, cy) = (0.5 * (lo(&xs) + hi(&xs)), 0.5 * (lo(&ys) + hi(&ys)));
    let half = 0.5 * (hi(&xs) - lo(&xs)).max(hi(&ys) - lo(&ys));
    ((cx - half)..(cx + half), (cy - half)..(cy + half))
}

fn draw<DB: DrawingBackend>(
    v: &PlacementView,
    root: &DrawingArea<DB, plotters::coord::Shift>,
) -> Result<(), String> {
    let (x, y) = extent(v);
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!(
                "the head's placement, from above ({}'s base frame, mm)",
                v.robot
            ),
            (FONT, 20),
        )
        .margin(14)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x, y)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("x (mm)")
        .y_desc("y (mm)")
        .label_style((FONT, 13))
        .draw()
        .map_err(e)?;
    // The base, and the arm's reach about it.
    let circle: Vec<(f64, f64)> = (0..=120)
        .map(|k| {
            let a = std::f64::consts::TAU * f64::from(k) / 120.0;
            (v.reach_m * 1e3 * a.cos(), v.reach_m * 1e3 * a.sin())
        })
        .collect();
    chart
        .draw_series(DashedLineSeries::new(
            circle,
            6,
            5,
            BLUE.mix(0.5).stroke_width(1),
        ))
        .map_err(e)?
        .label("the arm's reach")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], BLUE.mix(0.5)));
    chart
        .draw_series([Rectangle::new(
            [(-40.0, -40.0), (40.0, 40.0)],
            BLACK.filled(),
        )])
        .map_err(e)?
        .label("the robot's base")
        .legend(|(x, y)| Rectangle::new([(x, y - 4), (x + 8, y + 4)], BLACK.filled()));
    for (place, colour, what) in std::iter::once((&v.configured, CONFIGURED, "configured"))
        .chain(v.found.iter().map(|f| (f, FOUND, "found")))
    {
        draw_place(&mut chart, v, place, colour, what)?;
    }
    if let Some(found) = &v.found {
        let a = v.configured.base_from_head.translation.vector * 1e3;
        let b = found.base_from_head.translation.vector * 1e3;
        chart
            .draw_series(DashedLineSeries::new(
                [(a.x, a.y), (b.x, b.y)],
                8,
                5,
                FOUND.stroke_width(2),
            ))
            .map_err(e)?
            .label("move the head this way")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 18, y)], FOUND.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font((FONT, 13))
        .draw()
        .map_err(e)?;
    Ok(())
}

type PlacementChart<'a, DB> = ChartContext<
    'a,
    DB,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// One placement of the head: its outline, the way its face looks, its targets (reached or not).
fn draw_place<DB: DrawingBackend>(
    chart: &mut PlacementChart<'_, DB>,
    v: &PlacementView,
    place: &Place,
    colour: RGBColor,
    what: &str,
) -> Result<(), String> {
    let head: Vec<(f64, f64)> = v
        .outline
        .iter()
        .chain(v.outline.first())
        .map(|p| {
            let q = place.base_from_head * p;
            (q.x * 1e3, q.y * 1e3)
        })
        .collect();
    chart
        .draw_series(LineSeries::new(head, colour.stroke_width(2)))
        .map_err(e)?
        .label(format!("the head, {what}"))
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], colour.stroke_width(2)));
    // The way the face looks: an arrow from the head's centre.
    let c = place.base_from_head * Point3::origin();
    let f = place.base_from_head * Point3::from(v.face * 0.12);
    chart
        .draw_series([PathElement::new(
            [(c.x * 1e3, c.y * 1e3), (f.x * 1e3, f.y * 1e3)],
            colour.stroke_width(3),
        )])
        .map_err(e)?;
    chart
        .draw_series([Text::new(
            "face",
            (f.x * 1e3, f.y * 1e3),
            (FONT, 13).into_font().color(&colour),
        )])
        .map_err(e)?;
    for (name, head_from_coil, reached) in &place.targets {
        let p = place.base_from_head * Point3::from(head_from_coil.translation.vector);
        let at = (p.x * 1e3, p.y * 1e3);
        let mark = if *reached { colour } else { REFUSED };
        let label = if *reached {
            name.clone()
        } else {
            format!("{name} (not reached)")
        };
        // The dot on the coil's centre, its name beside it.
        chart
            .draw_series([EmptyElement::at(at)
                + Circle::new((0, 0), 5, mark.filled())
                + Text::new(label, (8, -6), (FONT, 13).into_font().color(&mark))])
            .map_err(e)?;
    }
    Ok(())
}

/// The drawing as PNG.
pub fn png(v: &PlacementView) -> Result<Vec<u8>, PlotError> {
    font()?;
    let draw_err = |detail: String| PlotError::Draw {
        figure: "placement",
        detail,
    };
    let mut rgb = vec![0u8; SIZE.0 as usize * SIZE.1 as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(e).map_err(draw_err)?;
        draw(v, &root).map_err(draw_err)?;
        root.present().map_err(e).map_err(draw_err)?;
    }
    let mut png = Vec::new();
    image::ImageEncoder::write_image(
        image::codecs::png::PngEncoder::new(&mut png),
        &rgb,
        SIZE.0,
        SIZE.1,
        image::ExtendedColorType::Rgb8,
    )
    .map_err(|err| draw_err(err.to_string()))?;
    Ok(png)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;

    /// The drawing, decoded.
    fn decoded(png: &[u8]) -> image::RgbImage {
        image::load_from_memory(png).unwrap().to_rgb8()
    }

    #[test]
    fn the_heads_the_targets_and_the_move_are_drawn_in_their_colours() {
        let outline: Vec<Point3<f64>> = (0..48)
            .map(|k| {
                let a = std::f64::consts::TAU * f64::from(k) / 48.0;
                Point3::new(0.075 * a.cos(), 0.095 * a.sin(), 0.0)
            })
            .collect();
        let coil = Isometry3::translation(0.0, 0.0, 0.11);
        let view = PlacementView {
            robot: "ur3e".into(),
            reach_m: 0.457,
            outline,
            face: Vector3::y(),
            configured: Place {
                base_from_head: Isometry3::translation(0.45, -0.1, 0.0),
                targets: vec![("o1".into(), coil, false)],
            },
            found: Some(Place {
                base_from_head: Isometry3::new(Vector3::new(0.3, -0.1, 0.0), Vector3::z() * 0.5),
                targets: vec![("o1".into(), coil, true)],
            }),
        };
        let img = decoded(&png(&view).unwrap());
        assert_eq!(img.dimensions(), SIZE);
        let count = |c: RGBColor| {
            img.pixels()
                .filter(|p| {
                    (i32::from(p[0]) - i32::from(c.0)).abs() < 30
                        && (i32::from(p[1]) - i32::from(c.1)).abs() < 30
                        && (i32::from(p[2]) - i32::from(c.2)).abs() < 30
                })
                .count()
        };
        // Both heads' outlines and arrows, the refused target red, the found one green.
        assert!(count(CONFIGURED) > 300, "{}", count(CONFIGURED));
        assert!(count(FOUND) > 300, "{}", count(FOUND));
        assert!(count(REFUSED) > 50, "{}", count(REFUSED));
        // Without a search, no green.
        let alone = PlacementView {
            found: None,
            ..view
        };
        let img = decoded(&png(&alone).unwrap());
        let green = img
            .pixels()
            .filter(|p| p[1] > 120 && p[0] < 60 && p[2] < 90)
            .count();
        assert_eq!(green, 0);
    }
}
