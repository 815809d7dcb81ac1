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
    /// The registration's normal matrix is singular: the data fix no pose.
    #[error(
        "the landmarks and the sweep leave the head's pose unfixed: touch three landmarks apart"
    )]
    Unconstrained,
    /// A landmark lies on a scan's cut: the scan does not hold it.
    #[error(
        "landmark {name:?} lies where the scan cuts the head: the scan does not hold it (use \
         landmarks the scan holds)"
    )]
    LandmarkOnCut {
        /// Its name.
        name: String,
    },
    /// A landmark to touch that the image does not have.
    #[error("landmark {name:?} is not among the image's landmarks ([head.landmarks])")]
    NoImageLandmark {
        /// Its name.
        name: String,
    },
    /// The noise model is out of range.
    #[error("the registration's noise model: {0}")]
    Noise(String),
    /// A landmark the scalp is measured from lies far off it.
    #[error(
        "landmark {name:?} lies {:.1} mm {} the scalp (at most {:.0} mm): are the landmarks in \
         the image's frame (RAS) and units (mm)?",
        .distance_m.abs() * 1e3, if *.distance_m > 0.0 { "outside" } else { "inside" }, .limit_m * 1e3
    )]
    LandmarkOffScalp {
        /// Its name.
        name: String,
        /// Its signed distance from the scalp (positive outside), m.
        distance_m: f64,
        /// The most allowed, m.
        limit_m: f64,
    },
    /// The landmarks are not where a RAS frame has them.
    #[error("the landmarks are not in a RAS frame: {why} (swapped, or the image is LPS?)")]
    LandmarksNotRas {
        /// What is amiss.
        why: String,
    },
    /// Three points of a scalp curve on one line.
    #[error("the scalp curve from {from} to {to}: its third point lies on the line between them")]
    SectionDegenerate {
        /// Where it starts.
        from: String,
        /// Where it ends.
        to: String,
    },
    /// A scalp curve's plane leaves the head.
    #[error(
        "the scalp curve from {from} to {to} leaves the head model: is the scan cut off there?"
    )]
    SectionMissesScalp {
        /// Where it starts.
        from: String,
        /// Where it ends.
        to: String,
    },
    /// Cz did not settle halfway along both the midline and the central curve.
    #[error(
        "Cz did not settle between the nasion–inion and LPA–RPA curves (still moving {:.2} mm): \
         check the landmarks",
        .moved_m * 1e3
    )]
    CzUnsettled {
        /// How far it moved in the last round, m.
        moved_m: f64,
    },
    /// A target outside the head.
    #[error(
        "the target lies {:.1} mm outside the scalp: a target is a point in the head (is it in \
         the image's frame, RAS, in mm?)",
        .distance_m * 1e3
    )]
    TargetOutsideHead {
        /// Its distance outside the scalp, m.
        distance_m: f64,
    },
    /// The handle's direction is along the scalp's normal there, which leaves it undefined.
    #[error(
        "the handle's direction is along the scalp's normal at the target: give another (--handle)"
    )]
    HandleAlongNormal,
    /// A dose search asked for what it cannot do (a radius not a distance, a step not positive).
    #[error("the dose search's reach and steps must be positive distances and angles: {0}")]
    BadSearch(String),
    /// No place the dose search tried gives a field at the target (it lies outside the sphere
    /// fitted under the coil).
    #[error(
        "no dose at the target from the coil over it: the target lies outside the sphere the \
         head is taken to be under the coil (is it in the head?)"
    )]
    NoDose,
    /// The scalp rises around the target so the coil cannot come near enough.
    #[error(
        "no coil fits over the target: the scalp around it would hold the coil {:.1} mm farther \
         off than asked (at most {:.0} mm){}",
        .lift_m * 1e3, .limit_m * 1e3,
        match .nearest_fit {
            Some((p, d)) => format!(
                "; the nearest scalp point where it fits is {:.1} mm away, at ({:.1}, {:.1}, {:.1}) mm",
                d * 1e3, p.x * 1e3, p.y * 1e3, p.z * 1e3
            ),
            None => " and none within 60 mm does".to_string(),
        }
    )]
    NoCoilFits {
        /// How far it would have to be lifted, m.
        lift_m: f64,
        /// The most allowed, m.
        limit_m: f64,
        /// The nearest scalp point where it fits and its distance from the target's, m.
        nearest_fit: Option<(mocomp_geom::nalgebra::Point3<f64>, f64)>,
    },
}
