//! What mocomp's experiment (`mocomp demo`) writes: [`demo`] (the summary, its Markdown and the
//! CSV of every tick) and [`plots`] (the figures, PNG and SVG); a TMS session's report
//! ([`session`]: one HTML page from its pulse log); the head's placement drawn ([`placement`]).
//!
//! **Limits.** Writes what an experiment or a session produced; runs nothing and connects to
//! nothing.

pub mod demo;
pub mod placement;
pub mod plots;
pub mod session;
