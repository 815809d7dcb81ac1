//! The paper's two-robot experiment ([`experiment`]): a head robot moves a phantom, the coil
//! robot follows it under a [`mocomp_control::Controller`], both on simulated controllers in
//! lockstep on one stepped clock, scored by the paper's `d`. It uses what the live session uses:
//! the one loop that drives a controller ([`mocomp_control::drive`], with a `Pace` of its own)
//! and the one calibration procedure ([`mocomp_calib::procedure`], with a `Station` of its own).
//! Beside it, the experiment's scripted clinical session ([`session_plan`]). The experiment's own parts: the head robot playing a
//! motion within its limits ([`head_drive`]), the oracle's knowledge of the true head
//! ([`oracle`]), and the error's split into the prediction's and the execution's share
//! ([`split`]); each tick's dose at the target, with a coil model, is measured against the
//! plans `mocomp_efield` makes ([`mocomp_efield::DosePlans`]).
//!
//! **Limits.** It knows no configuration file, no command line and no front end beyond the
//! contract (`mocomp-frontend`): the application turns its configuration into an
//! [`experiment::ExperimentConfig`]. Its simulators and connections are on loopback only; a run
//! is deterministic for its seed.

pub mod experiment;
pub mod head_drive;
pub mod oracle;
pub mod session_plan;
pub mod split;
