//! The whole pipeline for one frame: blobs, depth, back-projection, identification, pose.

use crate::blobs::{Blob, Frame, Gates, Labeler, ring_depth};
use crate::error::VisionError;
use crate::geometry::MarkerGeometry;
use crate::intrinsics::Intrinsics;
use crate::matching::{Assignment, match_points};
use crate::params::{Registration, TrackParams};
use crate::register::{kabsch, rms, three_point};
use mocomp_geom::nalgebra::{Isometry3, Point3};
use mocomp_geom::units::mm_to_m;
use mocomp_geom::{rotation_error, translation_error};
use std::fmt;

/// More candidate blobs than this and the frame is not searched (sunlight, a reflective surface).
pub const MAX_CANDIDATES: usize = 64;

/// What became of a blob.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlobStatus {
    /// Smaller than `blob_area_min`.
    TooSmall,
    /// Larger than `blob_area_max`.
    TooLarge,
    /// Touches the image or scan-area border.
    OnEdge,
    /// No valid depth around it.
    NoDepth,
    /// A candidate that was not identified as a fiducial.
    Unmatched,
    /// Identified as fiducial `k` (0-based) of the geometry.
    Fiducial(usize),
}

/// A blob, what became of it, and its 3-D point when it had depth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlobResult {
    /// The blob.
    pub blob: Blob,
    /// Its fate.
    pub status: BlobStatus,
    /// Ring depth, mm (median), when it had one.
    pub depth_mm: Option<f64>,
    /// Its point in the camera (tracker) frame, metres.
    pub point: Option<Point3<f64>>,
}

/// Why a frame has no pose.
#[derive(Debug, Clone, PartialEq)]
pub enum NotFound {
    /// Fewer candidate blobs than fiducials needed.
    TooFewBlobs {
        /// Candidates with depth.
        candidates: usize,
        /// Fiducials needed.
        needed: usize,
    },
    /// Too many candidate blobs to search.
    TooManyBlobs {
        /// Candidates.
        candidates: usize,
    },
    /// No assignment of blobs fits the geometry within the tolerance.
    NoMatch {
        /// Candidates searched.
        candidates: usize,
    },
    /// Two different assignments fit equally well (symmetric geometry or coincidence).
    Ambiguous,
    /// The registration error is above the limit.
    FreTooLarge {
        /// The FRE, metres.
        fre_m: f64,
        /// The limit, metres.
        limit_m: f64,
    },
}

impl fmt::Display for NotFound {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NotFound::TooFewBlobs { candidates, needed } => write!(
                f,
                "{candidates} candidate blob(s) with depth, {needed} fiducials needed"
            ),
            NotFound::TooManyBlobs { candidates } => write!(
                f,
                "{candidates} candidate blobs, more than {MAX_CANDIDATES}: raise the IR threshold or narrow the scan area"
            ),
            NotFound::NoMatch { candidates } => write!(
                f,
                "no assignment of the {candidates} candidate blobs fits the marker geometry"
            ),
            NotFound::Ambiguous => {
                write!(f, "two different assignments fit the geometry: ambiguous")
            }
            NotFound::FreTooLarge { fre_m, limit_m } => write!(
                f,
                "fiducial registration error {:.2} mm exceeds the limit {:.2} mm",
                fre_m * 1e3,
                limit_m * 1e3
            ),
        }
    }
}

/// A found marker.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    /// `tracker_from_marker` (camera frame, metres).
    pub tracker_from_marker: Isometry3<f64>,
    /// Fiducial registration error (RMS), metres.
    pub fre_m: f64,
    /// For each fiducial of the geometry, the index of its blob in [`FrameResult::blobs`].
    pub fiducials: Vec<Option<usize>>,
}

/// The outcome of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// The pose, when found.
    pub detection: Option<Detection>,
    /// Why not, when not found.
    pub not_found: Option<NotFound>,
    /// Every blob with its fate.
    pub blobs: Vec<BlobResult>,
}

impl FrameResult {
    /// Blobs dropped for lack of depth.
    pub fn dropped_no_depth(&self) -> usize {
        self.blobs
            .iter()
            .filter(|b| b.status == BlobStatus::NoDepth)
            .count()
    }
}

/// The fiducial tracker: parameters, intrinsics, geometry and reusable scratch space.
#[derive(Debug)]
pub struct Tracker {
    intrinsics: Intrinsics,
    params: TrackParams,
    geometry: MarkerGeometry,
    gates: Gates,
    labeler: Labeler,
    blobs: Vec<Blob>,
    depth_scratch: Vec<u16>,
}

impl Tracker {
    /// A tracker; validates the parameters and intrinsics and clips the scan area to the image.
    pub fn new(
        intrinsics: Intrinsics,
        params: TrackParams,
        geometry: MarkerGeometry,
    ) -> Result<Self, VisionError> {
        intrinsics.validate("intrinsics")?;
        params.validate("tracking parameters")?;
        let (w, h) = (intrinsics.width, intrinsics.height);
        let area = match params.scan_area {
            Some([x0, y0, x1, y1]) => {
                let a = [x0.min(w), y0.min(h), x1.min(w), y1.min(h)];
                if a[0] >= a[2] || a[1] >= a[3] {
                    return Err(VisionError::Config {
                        what: "tracking parameters".into(),
                        message: format!(
                            "scan_area [{x0}, {y0}, {x1}, {y1}] lies outside the {w}×{h} image"
                        ),
                    });
                }
                a
            }
            None => [0, 0, w, h],
        };
        Ok(Self {
            intrinsics,
            params,
            gates: Gates {
                threshold: params.ir_threshold,
                depth_range: (params.depth_min_mm, params.depth_max_mm),
                area,
                weighting: params.centroid_weighting,
            },
            geometry,
            labeler: Labeler::new(),
            blobs: Vec::new(),
            depth_scratch: Vec::new(),
        })
    }

    /// The parameters.
    pub fn params(&self) -> &TrackParams {
        &self.params
    }

    /// The intrinsics.
    pub fn intrinsics(&self) -> &Intrinsics {
        &self.intrinsics
    }

    /// The marker geometry.
    pub fn geometry(&self) -> &MarkerGeometry {
        &self.geometry
    }

    /// The scan area in use `[x0, y0, x1, y1)`.
    pub fn scan_area(&self) -> [u32; 4] {
        self.gates.area
    }

    /// Processes one frame. Fails only when the frame does not fit the intrinsics; a frame without
    /// the marker is a result with `not_found` set.
    pub fn process(&mut self, frame: &Frame<'_>) -> Result<FrameResult, VisionError> {
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        if frame.width != w || frame.height != h {
            return Err(VisionError::SizeMismatch {
                what: "frame".into(),
                got_w: frame.width,
                got_h: frame.height,
                want_w: w,
                want_h: h,
            });
        }
        self.labeler.label(frame, &self.gates, &mut self.blobs);
        let (mut results, candidates, points) = self.measure_blobs(frame);
        let p = &self.params;
        let n = self.geometry.len();
        let max_missing = if n >= 4 {
            (p.max_missing as usize).min(n - 3)
        } else {
            0
        };
        let needed = n - max_missing;
        let not_found = |reason: NotFound, blobs: Vec<BlobResult>| FrameResult {
            detection: None,
            not_found: Some(reason),
            blobs,
        };
        if candidates.len() < needed {
            return Ok(not_found(
                NotFound::TooFewBlobs {
                    candidates: candidates.len(),
                    needed,
                },
                results,
            ));
        }
        if candidates.len() > MAX_CANDIDATES {
            return Ok(not_found(
                NotFound::TooManyBlobs {
                    candidates: candidates.len(),
                },
                results,
            ));
        }
        let tol = mm_to_m(p.match_tolerance_mm);
        let matches = match_points(&self.geometry, &points, tol, max_missing);
        let Some(best) = matches.best else {
            return Ok(not_found(
                NotFound::NoMatch {
                    candidates: candidates.len(),
                },
                results,
            ));
        };
        let limit = mm_to_m(p.max_fre_mm);
        let Some((pose, fre)) = self.register(&best, &points) else {
            return Ok(not_found(
                NotFound::NoMatch {
                    candidates: candidates.len(),
                },
                results,
            ));
        };
        // A runner-up with as many fiducials, an acceptable fit and a different pose: ambiguous.
        if let Some(second) = &matches.second
            && second.matched == best.matched
            && let Some((pose2, fre2)) = self.register(second, &points)
            && fre2 <= limit
            && (rotation_error(&pose, &pose2) > 2f64.to_radians()
                || translation_error(&pose, &pose2) > 2.0 * tol)
        {
            return Ok(not_found(NotFound::Ambiguous, results));
        }
        if fre > limit {
            return Ok(not_found(
                NotFound::FreTooLarge {
                    fre_m: fre,
                    limit_m: limit,
                },
                results,
            ));
        }
        let fiducials: Vec<Option<usize>> = best
            .pairs
            .iter()
            .map(|o| o.map(|j| candidates[j]))
            .collect();
        for (k, b) in fiducials.iter().enumerate() {
            if let Some(b) = b {
                results[*b].status = BlobStatus::Fiducial(k);
            }
        }
        Ok(FrameResult {
            detection: Some(Detection {
                tracker_from_marker: pose,
                fre_m: fre,
                fiducials,
            }),
            not_found: None,
            blobs: results,
        })
    }

    /// Each blob of the frame classified (too small, too large, on the edge, without depth) and,
    /// where it may be a fiducial, its point from the depth around it: the blobs' results, the
    /// candidates' indices among them, and their points.
    fn measure_blobs(
        &mut self,
        frame: &Frame<'_>,
    ) -> (Vec<BlobResult>, Vec<usize>, Vec<Point3<f64>>) {
        let p = &self.params;
        let mut results = Vec::with_capacity(self.blobs.len());
        let mut candidates: Vec<usize> = Vec::new();
        let mut points: Vec<Point3<f64>> = Vec::new();
        for b in &self.blobs {
            let status = if b.area < p.blob_area_min {
                BlobStatus::TooSmall
            } else if b.area > p.blob_area_max {
                BlobStatus::TooLarge
            } else if p.reject_edge_blobs && b.touches_edge {
                BlobStatus::OnEdge
            } else {
                BlobStatus::Unmatched
            };
            let mut r = BlobResult {
                blob: *b,
                status,
                depth_mm: None,
                point: None,
            };
            if status == BlobStatus::Unmatched {
                match ring_depth(
                    frame,
                    b.bbox,
                    p.ring_px,
                    (p.depth_min_mm, p.depth_max_mm),
                    p.ring_min_valid,
                    &mut self.depth_scratch,
                ) {
                    Some((d, _)) => {
                        let z = mm_to_m(d - p.ring_to_centre_mm);
                        let pt =
                            Point3::from(self.intrinsics.unproject(b.centroid.0, b.centroid.1, z));
                        r.depth_mm = Some(d);
                        r.point = Some(pt);
                        candidates.push(results.len());
                        points.push(pt);
                    }
                    None => r.status = BlobStatus::NoDepth,
                }
            }
            results.push(r);
        }
        (results, candidates, points)
    }

    /// The pose of an assignment by the configured method, with its FRE over all matched points.
    fn register(&self, a: &Assignment, points: &[Point3<f64>]) -> Option<(Isometry3<f64>, f64)> {
        let mut model = Vec::with_capacity(a.matched);
        let mut seen = Vec::with_capacity(a.matched);
        for (k, j) in a.pairs.iter().enumerate() {
            if let Some(j) = j {
                model.push(self.geometry.points[k]);
                seen.push(points[*j]);
            }
        }
        match self.params.registration {
            Registration::Kabsch => kabsch(&model, &seen),
            Registration::ThreePoint => {
                let pose = three_point(
                    &[model[0], model[1], model[2]],
                    &[seen[0], seen[1], seen[2]],
                )?;
                Some((pose, rms(&pose, &model, &seen)))
            }
        }
    }
}
