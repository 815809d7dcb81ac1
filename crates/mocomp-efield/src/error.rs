//! What can go wrong reading a coil or computing its field.

/// An error naming the file, line and field, or the geometry that will not do.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EfieldError {
    /// A coil file that cannot be read as one.
    #[error("{file}:{line}: {what}")]
    Ccd {
        /// The file, as named.
        file: String,
        /// The line (1 is the first).
        line: usize,
        /// What was wrong there.
        what: String,
    },
    /// A sphere that is not one (its radius not a positive, finite length).
    #[error("a sphere of radius {radius_m} m at {centre_m:?} m: not a sphere")]
    BadSphere {
        /// Its centre, m.
        centre_m: [f64; 3],
        /// Its radius, m.
        radius_m: f64,
    },
    /// No sphere fits the scalp given (too few points, or flat).
    #[error("no sphere: {what}")]
    NoSphere {
        /// What the points were.
        what: String,
    },
    /// A plan whose target gets no field to measure against.
    #[error("no dose: {what}")]
    NoField {
        /// Why.
        what: String,
    },
    /// The point asked about is not inside the sphere, or a dipole of the coil is not outside
    /// it: the model holds only for sources outside a conductor and fields inside it.
    #[error("{what}: the sphere model holds for a coil outside the head and points inside it")]
    Outside {
        /// Which point, how far from the centre against the radius.
        what: String,
    },
}
