//! What can be wrong with a head: its file, its numbers, its shape. Each error names the file
//! (as the caller named it) and, where there is one, the byte offset, element or index.

/// Why a head could not be read or built.
#[derive(Debug, thiserror::Error)]
pub enum HeadError {
    /// The bytes do not follow the format.
    #[error("{file}: {what}{}", offset.map(|o| format!(" (at byte {o})")).unwrap_or_default())]
    Format {
        /// The file.
        file: String,
        /// What was wrong.
        what: String,
        /// Where, when known.
        offset: Option<u64>,
    },
    /// The file declares more than mocomp reads (checked before anything is allocated).
    #[error("{file}: {count} {what}, more than the {limit} a head model may have")]
    TooLarge {
        /// The file.
        file: String,
        /// Vertices or triangles.
        what: &'static str,
        /// How many it declares.
        count: u64,
        /// The limit.
        limit: u64,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("{file}: vertex {vertex} is not finite ({coords:?})")]
    NotFinite {
        /// The file.
        file: String,
        /// Its index (0-based).
        vertex: usize,
        /// What it holds.
        coords: [f64; 3],
    },
    /// A triangle names a vertex that does not exist.
    #[error("{file}: triangle {triangle} uses vertex {index}, but there are {vertices}")]
    BadIndex {
        /// The file.
        file: String,
        /// The triangle (0-based).
        triangle: usize,
        /// The index it holds.
        index: i64,
        /// Vertices in the file.
        vertices: usize,
    },
    /// Nothing is left to be a head (no triangles, or all of them degenerate).
    #[error("{file}: {what}")]
    Empty {
        /// The file.
        file: String,
        /// What is missing.
        what: String,
    },
    /// The format carries no unit and none was given.
    #[error(
        "{file}: {format} carries no length unit: give it (--units mm or m; [head] units); it is {extent:.4} units across, which is {hint}"
    )]
    UnitsNeeded {
        /// The file.
        file: String,
        /// The format.
        format: &'static str,
        /// The largest extent of its bounding box, in the file's units.
        extent: f64,
        /// Which unit that extent makes a head.
        hint: &'static str,
    },
    /// The head, in the unit read or given, is not the size of a head.
    #[error(
        "{file}: the head is {extent_m:.3} m across in {unit}: a head is {min}–{max} m; {hint}"
    )]
    NotHeadSized {
        /// The file.
        file: String,
        /// The largest extent of its bounding box, metres.
        extent_m: f64,
        /// The unit it was read in.
        unit: &'static str,
        /// The smallest plausible extent, m.
        min: f64,
        /// The largest plausible extent, m.
        max: f64,
        /// What to check.
        hint: &'static str,
    },
    /// The mesh cannot be made into a closed surface with an inside.
    #[error("{file}: {what}")]
    Shape {
        /// The file.
        file: String,
        /// What was wrong.
        what: String,
    },
    /// An ellipsoid with a semi-axis that is not a positive, finite length.
    #[error("ellipsoid radii {radii:?} m: each must be positive and finite")]
    BadRadii {
        /// The radii given.
        radii: [f64; 3],
    },
    /// No ellipsoid fits the points (too few, or not round enough to close one).
    #[error("no ellipsoid fits the {points} points: {why}")]
    NoFit {
        /// How many points were given.
        points: usize,
        /// Why.
        why: &'static str,
    },
    /// A coil solid with a radius or thickness that is not a positive, finite length.
    #[error(
        "coil solid radius {radius} m, thickness {thickness} m: both must be positive and finite"
    )]
    BadCoil {
        /// Radius.
        radius: f64,
        /// Thickness.
        thickness: f64,
    },
    /// A coil casing that is no solid.
    #[error("coil casing {file}: {why}")]
    BadCasing {
        /// The file it was read from.
        file: String,
        /// What is wrong with it.
        why: String,
    },
}

impl HeadError {
    /// A format error in `file`, at `offset` when known.
    pub(crate) fn format(file: &str, what: impl Into<String>, offset: Option<u64>) -> Self {
        Self::Format {
            file: file.to_string(),
            what: what.into(),
            offset,
        }
    }
}
