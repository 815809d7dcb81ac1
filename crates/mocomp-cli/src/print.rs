//! Text formatting shared by the subcommands.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::Write;

/// A report as one JSON line (`json`) or as its text.
pub fn report<R: serde::Serialize + std::fmt::Display>(
    out: &mut dyn Write,
    r: &R,
    json: bool,
) -> anyhow::Result<()> {
    if json {
        writeln!(out, "{}", serde_json::to_string(r)?)?;
    } else {
        write!(out, "{r}")?;
    }
    Ok(())
}

/// A progress bar of `len` steps drawn with `template` (hidden when `quiet`).
pub fn bar(len: u64, template: &str, quiet: bool) -> ProgressBar {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(len)
    };
    bar.set_style(
        ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    bar
}
