//! What navigation refuses, named.

/// Why a calibration or a registration is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NavError {
    /// Too few pointer samples for a pivot calibration.
    #[error("{got} pointer samples: a pivot calibration needs at least {need}")]
    TooFewSamples {
        /// Samples given.
        got: usize,
        /// The least it needs.
        need: usize,
    },
    /// A sample is not a finite pose.
    #[error("pointer sample {index} is not a finite pose")]
    NotFinite {
        /// Its index.
        index: usize,
    },
    /// The pointer was not turned enough about the pivot to fix its tip.
    #[error(
        "the pointer turned through {:.1}° while pivoting: at least {:.0}° is needed to find its \
         tip (tilt it further about the pivot, in every direction)",
        .spread_rad.to_degrees(), .need_rad.to_degrees()
    )]
    SpreadTooSmall {
        /// How far it turned about two independent axes, rad.
        spread_rad: f64,
        /// The least allowed, rad.
        need_rad: f64,
    },
    /// Too many samples disagree with the pivot (the tip slipped, or the marker was poorly
    /// seen).
    #[error(
        "only {kept} of {of} pointer samples agree on one pivot (within {:.2} mm): the tip \
         slipped or the marker was poorly seen; pivot again",
        .within_m * 1e3
    )]
    TooManyOutliers {
        /// Samples kept.
        kept: usize,
        /// Samples given.
        of: usize,
        /// How far from the pivot a kept sample's tip was at most, m.
        within_m: f64,
    },
    /// The tips scatter too far about the pivot they agree on.
    #[error(
        "the pointer's tip scatters {:.2} mm RMS about the pivot (at most {:.1} mm): the tip \
         moved on the divot or the marker was poorly seen; pivot again",
        .rms_m * 1e3, .limit_m * 1e3
    )]
    PivotTooPoor {
        /// The kept tips' RMS distance from the pivot, m.
        rms_m: f64,
        /// The most allowed, m.
        limit_m: f64,
    },
    /// Fewer than three landmarks named in both the image and the tracked set.
    #[error(
        "{} landmark{} named in both the image and the touched set ({}): a registration needs three",
        .paired.len(), if .paired.len() == 1 { "" } else { "s" }, .paired.join(", ")
    )]
    TooFewLandmarks {
        /// The names found in both.
        paired: Vec<String>,
    },
    /// The landmarks lie (nearly) on one line, which leaves the rotation about it free.
    #[error(
        "the landmarks {} lie within {:.1} mm of one line: the rotation about it is not fixed \
         (add a landmark off that line, at least {:.0} mm from it)",
        .names.join(", "), .off_line_m * 1e3, .need_m * 1e3
    )]
    CollinearLandmarks {
        /// The landmarks' names.
        names: Vec<String>,
        /// Their RMS distance from the line that fits them best, m.
        off_line_m: f64,
        /// The least allowed, m.
        need_m: f64,
    },
    /// A landmark's position is not finite.
    #[error("landmark {name:?}: its position is not finite")]
    LandmarkNotFinite {
        /// Its name.
        name: String,
    },
    /// A landmark named twice in one set.
    #[error("landmark {name:?} is named twice in the {set}")]
    DuplicateLandmark {
        /// Its name.
        name: String,
        /// `image` or `touched`.
        set: &'static str,
    },
    /// A swept point is not finite.
    #[error("surface point {index} is not finite")]
    SurfacePointNotFinite {
        /// Its index.
        index: usize,
    },
    /// Too few swept points lie near the scalp.
    #[error(
        "{near} swept points lie within {:.0} mm of the scalp ({far} farther): the surface \
         registration needs {need}; sweep the pointer over the scalp, touching it",
        .within_m * 1e3
    )]
    TooFewSurfacePoints {
        /// Points near the scalp.
        near: usize,
        /// Points left out as too far.
        far: usize,
        /// The fewest it needs.
        need: usize,
        /// How near counts, m.
        within_m: f64,
    },
    /// The swept points leave a motion of the head free (all on one side, or on a patch that
    /// slides along itself).
    #[error(
        "the swept points leave {free} free (all on one side of the head?): sweep the forehead, \
         both sides and the crown"
    )]
    SurfaceUnconstrained {
        /// The motion they do not fix.
        free: String,
    },
}
