//! A [`PoseSource`] for the control loop that turns a stream of frames into timestamped
//! `tracker_from_marker` samples.

use crate::blobs::Frame;
use crate::error::VisionError;
use crate::pipeline::Tracker;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{PoseSample, PoseSource};

/// A frame with its acquisition time.
#[derive(Debug, Clone, PartialEq)]
pub struct TimedFrame {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// IR image.
    pub ir: Vec<u16>,
    /// Depth image, mm.
    pub depth: Vec<u16>,
    /// Acquisition time, seconds on the loop's monotonic clock.
    pub acquired_s: f64,
}

/// Where frames come from. `next_frame` never blocks.
pub trait FrameSource {
    /// The next frame that has arrived, if any.
    fn next_frame(&mut self) -> Option<TimedFrame>;
}

impl FrameSource for std::sync::mpsc::Receiver<TimedFrame> {
    fn next_frame(&mut self) -> Option<TimedFrame> {
        self.try_recv().ok()
    }
}

impl FrameSource for std::collections::VecDeque<TimedFrame> {
    fn next_frame(&mut self) -> Option<TimedFrame> {
        self.pop_front()
    }
}

/// Counters of what the source did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct VisionCounters {
    /// Frames processed.
    pub processed: u64,
    /// Frames skipped because a newer one had arrived.
    pub skipped: u64,
    /// Frames in which the marker was found.
    pub found: u64,
    /// Frames that could not be processed (wrong size).
    pub rejected: u64,
}

/// Tracks the marker in the newest frame on each call.
#[derive(Debug)]
pub struct VisionPoseSource<S> {
    tracker: Tracker,
    source: S,
    last_pose: Option<Isometry3<f64>>,
    last_error: Option<VisionError>,
    counters: VisionCounters,
}

impl<S: FrameSource> VisionPoseSource<S> {
    /// A source that processes frames from `source` with `tracker`.
    pub fn new(tracker: Tracker, source: S) -> Self {
        Self {
            tracker,
            source,
            last_pose: None,
            last_error: None,
            counters: VisionCounters::default(),
        }
    }

    /// What happened so far.
    pub fn counters(&self) -> VisionCounters {
        self.counters
    }

    /// The last frame error (a frame of the wrong size), if any.
    pub fn last_error(&self) -> Option<&VisionError> {
        self.last_error.as_ref()
    }
}

impl<S: FrameSource> PoseSource for VisionPoseSource<S> {
    /// Processes the newest frame (older ones that queued up are skipped and counted). When the
    /// marker is not found the sample is invalid and carries the last known pose.
    fn latest(&mut self) -> Option<PoseSample> {
        let mut newest = self.source.next_frame()?;
        while let Some(f) = self.source.next_frame() {
            self.counters.skipped += 1;
            newest = f;
        }
        let frame = match Frame::new(newest.width, newest.height, &newest.ir, &newest.depth) {
            Ok(f) => f,
            Err(e) => {
                self.counters.rejected += 1;
                self.last_error = Some(e);
                return None;
            }
        };
        let result = match self.tracker.process(&frame) {
            Ok(r) => r,
            Err(e) => {
                self.counters.rejected += 1;
                self.last_error = Some(e);
                return None;
            }
        };
        self.counters.processed += 1;
        match result.detection {
            Some(d) => {
                self.counters.found += 1;
                self.last_pose = Some(d.tracker_from_marker);
                Some(PoseSample {
                    tracker_from_marker: d.tracker_from_marker,
                    acquired_s: newest.acquired_s,
                    valid: true,
                    error_m: d.fre_m,
                })
            }
            None => Some(PoseSample {
                tracker_from_marker: self.last_pose.unwrap_or_else(Isometry3::identity),
                acquired_s: newest.acquired_s,
                valid: false,
                error_m: f64::NAN,
            }),
        }
    }
}
