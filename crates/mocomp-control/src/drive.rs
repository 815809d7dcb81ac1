//! The one loop that drives a [`Controller`]: the live session and the lockstep experiment differ
//! only in their [`Pace`], which says when each cycle is due (a new robot state in real time, or
//! the next tick of a stepped clock), which robot and tracker the controller talks to, and what
//! happens after each cycle (the live one queues the record for its logger; the lockstep one
//! steps the simulated world and scores it).

use crate::{Controller, CycleRecord, LoopParams};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, PoseSource};
use mocomp_robot::Robot;

/// How a loop is paced.
pub trait Pace {
    /// What goes wrong.
    type Error;
    /// Waits until the next cycle is due and returns its time on the loop's clock (s); `None`:
    /// the loop ends.
    fn next_cycle(&mut self) -> Result<Option<f64>, Self::Error>;
    /// The robot the controller commands and the tracker it reads.
    fn loop_io(&mut self) -> (&mut dyn Robot, &mut dyn PoseSource);
    /// After the cycle, with its record (the command has been sent).
    fn cycle_done(&mut self, record: CycleRecord) -> Result<(), Self::Error>;
    /// What the operator asks before the next cycle (none by default). Must not block, lock or
    /// allocate: it runs on the loop's thread.
    fn requests(&mut self) -> Requests {
        Requests::default()
    }
}

/// The operator's requests to a running loop, applied before a cycle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Requests {
    /// Hold (`true`) or resume, when it changed.
    pub hold: Option<bool>,
    /// New loop parameters, validated.
    pub params: Option<LoopParams>,
    /// A new goal (`head_from_coil`), checked.
    pub goal: Option<Isometry3<f64>>,
    /// The session's drift monitor calls the calibration invalid (offset m, angle rad): the loop
    /// holds (latched: a run does not recalibrate).
    pub calibration_invalid: Option<(f64, f64)>,
    /// Free-drive on or handed back, when it changed.
    pub freedrive: Option<bool>,
    /// The operator re-armed a latched fault, the robot's own recovery done.
    pub rearm: bool,
}

/// Runs `controller` at `pace` until the pace ends it. Each record carries the cycle's compute
/// time (the command's socket write included) on `stopwatch`, the caller's monotonic clock: this
/// crate reads no clock of its own. Allocates nothing, locks nothing and logs nothing itself: what
/// a pace does around the cycle is its own.
pub fn drive<P: Pace + ?Sized>(
    controller: &mut dyn Controller,
    pace: &mut P,
    stopwatch: &dyn Clock,
) -> Result<(), P::Error> {
    while let Some(now) = pace.next_cycle()? {
        let requests = pace.requests();
        if let Some(hold) = requests.hold {
            controller.set_operator_hold(hold);
        }
        if let Some(params) = &requests.params {
            controller.set_params(params);
        }
        if let Some(goal) = &requests.goal {
            controller.set_goal(goal);
        }
        if let Some(on) = requests.freedrive {
            controller.set_freedrive(on);
        }
        if requests.rearm {
            controller.rearm();
        }
        if requests.calibration_invalid.is_some() {
            controller.set_calibration_invalid(requests.calibration_invalid);
        }
        let started = stopwatch.now_s();
        let (robot, source) = pace.loop_io();
        let mut record = controller.cycle(now, robot, source);
        record.compute_ns = seconds_to_ns(stopwatch.now_s() - started);
        pace.cycle_done(record)?;
    }
    Ok(())
}

/// A duration in whole nanoseconds, 0 for a clock that went back or gave no number.
fn seconds_to_ns(s: f64) -> u64 {
    if s.is_finite() && s > 0.0 {
        // `as` saturates at u64::MAX, which no cycle reaches.
        (s * 1e9).round() as u64
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::Isometry3;
    use mocomp_testkit::mem::{MemRobot, ScriptedPoses};

    /// A stepped pace over an in-memory robot: `n` cycles of `period`, the robot ticked after each.
    struct Stepped {
        robot: MemRobot,
        source: ScriptedPoses,
        t: f64,
        period: f64,
        left: usize,
        seen: Vec<(f64, bool)>,
    }

    impl Pace for Stepped {
        type Error = String;
        fn next_cycle(&mut self) -> Result<Option<f64>, String> {
            if self.left == 0 {
                return Ok(None);
            }
            self.left -= 1;
            Ok(Some(self.t))
        }
        fn loop_io(&mut self) -> (&mut dyn Robot, &mut dyn PoseSource) {
            (&mut self.robot, &mut self.source)
        }
        fn cycle_done(&mut self, r: CycleRecord) -> Result<(), String> {
            self.seen.push((r.t, r.compute_ns > 0));
            self.t += self.period;
            self.robot.tick(self.t);
            Ok(())
        }
    }

    /// Counts its cycles and the times it was given, and the operator's holds.
    struct Counting(Vec<f64>, Vec<(usize, bool)>);

    impl Controller for Counting {
        fn name(&self) -> &'static str {
            "counting"
        }
        fn cycle(
            &mut self,
            now: f64,
            robot: &mut dyn Robot,
            _: &mut dyn PoseSource,
        ) -> CycleRecord {
            self.0.push(now);
            // A state is there: the pace ticked the robot before each cycle.
            assert!(robot.state().is_some());
            // Work that takes measurable time.
            std::thread::sleep(std::time::Duration::from_micros(50));
            CycleRecord::new(now, crate::Mode::Tracking, [0.0; 6])
        }

        fn set_operator_hold(&mut self, hold: bool) {
            self.1.push((self.0.len(), hold));
        }
    }

    #[test]
    fn each_cycle_runs_at_the_paces_time_and_its_record_comes_back_timed() {
        let q = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0];
        let mut robot = MemRobot::at(q, Isometry3::identity(), 0.008);
        robot.tick(0.0);
        let mut pace = Stepped {
            robot,
            source: ScriptedPoses::new(60.0, 0.02, Box::new(|_| Some(Isometry3::identity()))),
            t: 0.0,
            period: 0.008,
            left: 5,
            seen: Vec::new(),
        };
        let mut c = Counting(Vec::new(), Vec::new());
        drive(&mut c, &mut pace, &mocomp_geom::MonotonicClock::new()).unwrap();
        let expected: Vec<f64> = (0..5).map(|k| f64::from(k) * 0.008).collect();
        assert_eq!(c.0.len(), 5);
        for (a, b) in c.0.iter().zip(&expected) {
            assert!((a - b).abs() < 1e-12);
        }
        assert_eq!(pace.seen.len(), 5);
        assert!(pace.seen.iter().all(|(_, timed)| *timed));
        // The pace asked for nothing: nothing reached the controller.
        assert!(c.1.is_empty());
    }

    /// A stepped pace whose operator holds before cycle 2 and resumes before cycle 4.
    struct Asking(Stepped, usize);

    impl Pace for Asking {
        type Error = String;
        fn next_cycle(&mut self) -> Result<Option<f64>, String> {
            self.0.next_cycle()
        }
        fn loop_io(&mut self) -> (&mut dyn Robot, &mut dyn PoseSource) {
            self.0.loop_io()
        }
        fn cycle_done(&mut self, r: CycleRecord) -> Result<(), String> {
            self.1 += 1;
            self.0.cycle_done(r)
        }
        fn requests(&mut self) -> Requests {
            Requests {
                hold: match self.1 {
                    2 => Some(true),
                    4 => Some(false),
                    _ => None,
                },
                ..Requests::default()
            }
        }
    }

    #[test]
    fn the_operators_requests_reach_the_controller_before_the_cycle_they_are_for() {
        let q = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0];
        let mut robot = MemRobot::at(q, Isometry3::identity(), 0.008);
        robot.tick(0.0);
        let stepped = Stepped {
            robot,
            source: ScriptedPoses::new(60.0, 0.02, Box::new(|_| Some(Isometry3::identity()))),
            t: 0.0,
            period: 0.008,
            left: 6,
            seen: Vec::new(),
        };
        let mut pace = Asking(stepped, 0);
        let mut c = Counting(Vec::new(), Vec::new());
        drive(&mut c, &mut pace, &mocomp_geom::MonotonicClock::new()).unwrap();
        // (cycles run before the request, the request)
        assert_eq!(c.1, vec![(2, true), (4, false)]);
    }
}
