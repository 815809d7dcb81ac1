//! What drives the coil robot, one call per robot cycle: mocomp's [`crate::Compensator`], and
//! any other controller compared with it (the paper's pipeline, in `mocomp-sim`). The driver (a
//! live loop or a lockstep experiment) calls [`Controller::cycle`] and owns the clock and the
//! logging.

use crate::compensator::{Compensator, CycleRecord};
use crate::config::LoopParams;
use mocomp_geom::PoseSource;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_robot::Robot;

/// A controller of the coil robot.
pub trait Controller {
    /// Its name in reports.
    fn name(&self) -> &'static str;

    /// One cycle at time `now` (s, the clock of the robot's state and the tracker's samples):
    /// takes the newest samples and state and sends at most one command.
    fn cycle(
        &mut self,
        now: f64,
        robot: &mut dyn Robot,
        source: &mut dyn PoseSource,
    ) -> CycleRecord;

    /// The operator's hold (`true`) or resume, from the next cycle. A controller without an
    /// operator's hold (the paper's pipeline) ignores it.
    fn set_operator_hold(&mut self, _hold: bool) {}

    /// New loop parameters (validated by the caller), from the next cycle. A controller without
    /// them (the paper's pipeline) ignores them.
    fn set_params(&mut self, _params: &LoopParams) {}

    /// A new goal (`head_from_coil`, checked by the caller), from the next cycle. A controller
    /// without one (the paper's pipeline, which has its own) ignores it.
    fn set_goal(&mut self, _head_from_coil: &Isometry3<f64>) {}

    /// The calibration is no longer valid (the drift monitor's offset, m and rad), or valid
    /// again (`None`, after a new calibration), from the next cycle. A controller without a
    /// supervisor (the paper's pipeline) ignores it.
    fn set_calibration_invalid(&mut self, _offset: Option<(f64, f64)>) {}

    /// Free-drive on (`true`) or handed back (`false`), from the next cycle. A controller
    /// without it (the paper's pipeline) ignores it.
    fn set_freedrive(&mut self, _on: bool) {}

    /// The operator's re-arm after a latched fault, from the next cycle (the robot's own
    /// recovery done by the caller). A controller without latched faults ignores it.
    fn rearm(&mut self) {}
}

impl Controller for Compensator {
    fn name(&self) -> &'static str {
        "mocomp"
    }

    fn cycle(
        &mut self,
        now: f64,
        robot: &mut dyn Robot,
        source: &mut dyn PoseSource,
    ) -> CycleRecord {
        Compensator::cycle(self, now, robot, source)
    }

    fn set_operator_hold(&mut self, hold: bool) {
        Compensator::set_operator_hold(self, hold);
    }

    fn set_params(&mut self, params: &LoopParams) {
        Compensator::set_params(self, *params);
    }

    fn set_goal(&mut self, head_from_coil: &Isometry3<f64>) {
        // Checked by the caller with the same check: a refusal here keeps the goal as it was.
        Compensator::set_goal(self, head_from_coil).ok();
    }

    fn set_calibration_invalid(&mut self, offset: Option<(f64, f64)>) {
        Compensator::set_calibration_invalid(self, offset);
    }

    fn set_freedrive(&mut self, on: bool) {
        Compensator::set_freedrive(self, on);
    }

    fn rearm(&mut self) {
        Compensator::rearm(self);
    }
}
