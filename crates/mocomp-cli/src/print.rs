//! Text formatting shared by the subcommands.

use indicatif::{ProgressBar, ProgressStyle};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{rows_from_iso, ur_pose_from_iso};
use std::io::Write;

/// Numbers in fixed-width columns.
pub fn row(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:>10.6}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// A title, the 4×4 matrix of a transform and, when `with_pose`, its UR pose vector.
pub fn transform(
    out: &mut (impl Write + ?Sized),
    title: &str,
    t: &Isometry3<f64>,
    with_pose: bool,
) -> std::io::Result<()> {
    writeln!(out, "{title}:")?;
    for r in rows_from_iso(t) {
        writeln!(out, "  [{} ]", row(&r))?;
    }
    if with_pose {
        writeln!(
            out,
            "  pose [x, y, z, rx, ry, rz] (m, rad): [{}]",
            row(&ur_pose_from_iso(t))
        )?;
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
