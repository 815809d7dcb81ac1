//! What mocomp's experiment (`mocomp demo`) writes: [`demo`] (the summary, its Markdown and the
//! CSV of every tick) and [`plots`] (the figures, PNG and SVG).
//!
//! **Limits.** Writes what an experiment produced; runs nothing and connects to nothing.

pub mod demo;
pub mod plots;
