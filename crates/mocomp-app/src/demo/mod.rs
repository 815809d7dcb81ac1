//! `mocomp demo`: its settings over the configuration, the experiment's configuration from
//! the file, its run with what watches it, and its recording.

pub mod experiment_config;
pub mod options;
pub mod record;
pub mod run;
