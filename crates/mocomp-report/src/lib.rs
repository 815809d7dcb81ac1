//! What mocomp's experiment (`mocomp demo`) writes: [`demo`] (the summary, its Markdown and the
//! CSV of every tick) and [`plots`] (the figures, PNG and SVG).

pub mod demo;
pub mod plots;
