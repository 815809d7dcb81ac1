//! What mocomp's experiment (`mocomp demo`) writes: [`demo`] (the summary, its Markdown and the
//! CSV of every tick) and [`plots`] (the figures, PNG and SVG); and a TMS session's report
//! ([`session`]: one HTML page from its pulse log).
//!
//! **Limits.** Writes what an experiment or a session produced; runs nothing and connects to
//! nothing.

pub mod demo;
pub mod plots;
pub mod session;
