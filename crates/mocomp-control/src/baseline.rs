//! The model of the paper's MATLAB pipeline as a [`Controller`]: every `period_s` it takes the
//! newest valid sample, computes `Z = Y · S_T_H · H_T_C,g · X⁻¹` and its IK solution of least
//! angle sum, and `compute_delay_s` later sends a movej there (no prediction, no checks).

use crate::{Controller, CycleRecord, Event, LoopConfig, Mode, Reason};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{PoseSample, PoseSource};
use mocomp_kin::{Arm, BranchPolicy, Metric, Selection};
use mocomp_robot::Robot;

/// The `paper` controller's model of the original pipeline.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PaperController {
    /// Loop period, s (tracking, IK and communication in MATLAB).
    pub period_s: f64,
    /// From taking a sample to sending the move, s.
    pub compute_delay_s: f64,
    /// movej joint speed, rad/s.
    pub joint_speed_rad_s: f64,
    /// movej joint acceleration, rad/s².
    pub joint_accel_rad_s2: f64,
}

impl Default for PaperController {
    /// A 10 Hz loop with 80 ms of computation, and URScript's default movej (1.05 rad/s,
    /// 1.4 rad/s²).
    fn default() -> Self {
        Self {
            period_s: 0.1,
            compute_delay_s: 0.08,
            joint_speed_rad_s: 1.05,
            joint_accel_rad_s2: 1.4,
        }
    }
}

/// The paper's pipeline.
#[derive(Debug, Clone)]
pub struct PaperPipeline {
    cfg: PaperController,
    arm: Arm,
    base_from_tracker: Isometry3<f64>,
    head_from_coil_goal: Isometry3<f64>,
    coil_from_flange: Isometry3<f64>,
    /// The first cycle's time: the pipeline's loop runs from it.
    start_s: Option<f64>,
    next_loop_s: f64,
    newest: Option<PoseSample>,
    /// A move computed and not yet sent: when it is due, its joints, its sample's time.
    pending: Option<(f64, [f64; 6], f64)>,
    last_horizon_s: f64,
    /// Whether the robot was stopped at the previous cycle (for the event when it stops).
    was_faulted: bool,
}

impl PaperPipeline {
    /// The pipeline for `arm` with the frames of `loop_cfg` (its calibration and goal).
    pub fn new(cfg: PaperController, arm: Arm, loop_cfg: &LoopConfig) -> Self {
        Self {
            cfg,
            arm,
            base_from_tracker: loop_cfg.base_from_tracker,
            head_from_coil_goal: loop_cfg.head_from_coil_goal,
            coil_from_flange: loop_cfg.flange_from_coil.inverse(),
            start_s: None,
            was_faulted: false,
            next_loop_s: 0.0,
            newest: None,
            pending: None,
            last_horizon_s: f64::NAN,
        }
    }
}

impl Controller for PaperPipeline {
    fn name(&self) -> &'static str {
        "paper"
    }

    fn cycle(
        &mut self,
        now: f64,
        robot: &mut dyn Robot,
        source: &mut dyn PoseSource,
    ) -> CycleRecord {
        let t = now - *self.start_s.get_or_insert(now);
        while let Some(s) = source.latest() {
            if s.valid {
                self.newest = Some(s);
            }
        }
        let state = robot.state().map(|s| (s.actual_q, s.actual_qd));
        let q_now = state.map(|s| s.0);
        if t + 1e-9 >= self.next_loop_s {
            self.next_loop_s += self.cfg.period_s;
            if let (Some(s), Some(q)) = (self.newest, q_now) {
                // Z = Y · S_T_H · H_T_C,g · X⁻¹, to the IK solution of least angle sum.
                let z = self.base_from_tracker
                    * s.tracker_from_marker
                    * self.head_from_coil_goal
                    * self.coil_from_flange;
                let select = Selection {
                    metric: Metric::WeightedSum([1.0; 6]),
                    branch: BranchPolicy::Any,
                    limit_margin: 0.0,
                };
                if let Ok(c) = self.arm.ik_closest(&z, &q, &select) {
                    let due = now + self.cfg.compute_delay_s;
                    self.pending = Some((due, c.joints, s.acquired_s));
                }
            }
        }
        let mut sent_q = q_now.unwrap_or([f64::NAN; 6]);
        // The pipeline knows nothing of the robot's safety: a stopped robot refuses its moves,
        // and it goes on sending (its keep-alive reaches the controller; the record shows the
        // stop).
        let fault = robot.state().and_then(|s| s.fault());
        match self.pending {
            Some((due, q, acquired)) if now + 1e-9 >= due => {
                if robot
                    .move_joints(&q, self.cfg.joint_speed_rad_s, self.cfg.joint_accel_rad_s2)
                    .is_err()
                {
                    robot.keep_alive().ok();
                }
                self.last_horizon_s = now - acquired;
                self.pending = None;
                sent_q = q;
            }
            _ => {
                robot.keep_alive().ok();
            }
        }
        let mode = fault.map_or(Mode::Tracking, |f| Mode::Faulted(Reason::Robot(f)));
        let mut rec = CycleRecord::new(now, mode, sent_q);
        rec.robot_s = robot.state().map_or(f64::NAN, |s| s.controller_s);
        if let Some(f) = fault
            && !self.was_faulted
        {
            rec.event = Some(Event::Hold(Reason::Robot(f)));
        }
        self.was_faulted = fault.is_some();
        rec.sample_age_s = self.newest.map_or(f64::NAN, |s| now - s.acquired_s);
        rec.horizon_s = self.last_horizon_s;
        // What the pipeline knows, for the record: the arm as measured, its goal, and the head
        // as its newest sample has it (it predicts nothing).
        if let Some((q, qd)) = state {
            (rec.q_actual, rec.qd_actual) = (q, qd);
        }
        rec.head_from_coil_goal = self.head_from_coil_goal;
        rec.head_now = self.newest.map(|s| s.tracker_from_marker);
        rec
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)] // test code
    use super::*;
    use mocomp_kin::Model;
    use mocomp_testkit::mem::{MemRobot, ScriptedPoses};
    use mocomp_testkit::scene::{
        base_from_tracker, flange_from_coil, head_from_coil_goal, head_rest,
    };

    #[test]
    fn it_moves_to_the_newest_sample_s_goal_once_per_period_after_its_delay() {
        let arm = Arm::new(Model::Ur3e);
        let cfg = LoopConfig::new(
            base_from_tracker(),
            flange_from_coil(),
            head_from_coil_goal(),
            0.008,
        );
        let goal_flange = head_rest() * head_from_coil_goal() * flange_from_coil().inverse();
        let q0 = arm
            .ik_closest(
                &goal_flange,
                &[0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
                &Selection::tracking(0.05),
            )
            .unwrap()
            .joints;
        let mut robot = MemRobot::at(q0, arm.fk(&q0), 0.008);
        let tracker_from_head = base_from_tracker().inverse() * head_rest();
        let mut poses = ScriptedPoses::new(60.0, 0.02, Box::new(move |_| Some(tracker_from_head)));
        let mut p = PaperPipeline::new(PaperController::default(), arm, &cfg);
        let mut moves = Vec::new();
        for k in 0..=50 {
            let t = 1.0 + k as f64 * 0.008;
            poses.now = t;
            robot.tick(t);
            let before = robot.seq;
            let measured = robot.state().unwrap().actual_q;
            let rec = p.cycle(t, &mut robot, &mut poses);
            if robot.seq != before {
                moves.push((t, rec.horizon_s));
            }
            // The record has the arm as measured and the head as the newest sample has it.
            assert_eq!(rec.q_actual, measured);
            assert_eq!(rec.head_from_coil_goal, head_from_coil_goal());
            let head = rec.head_now.unwrap();
            assert!(
                (head.translation.vector - tracker_from_head.translation.vector).norm() < 1e-12
            );
        }
        // A 10 Hz loop from t = 1.0 s, each move 80 ms after its tick: 1.08, 1.18, 1.28, 1.38.
        let times: Vec<f64> = moves
            .iter()
            .map(|m| (m.0 * 1000.0).round() / 1000.0)
            .collect();
        assert_eq!(times, vec![1.08, 1.184, 1.28, 1.384], "{moves:?}");
        // Every other cycle kept the program alive; the move goes to the goal's IK solution.
        assert_eq!(robot.keep_alives as usize, 51 - moves.len());
        let q = robot.last_move.unwrap();
        let reached = arm.fk_flange(&q);
        assert!((reached.translation.vector - goal_flange.translation.vector).norm() < 1e-9);
        // The horizon is the newest sample's age when the move went out (≥ the 20 ms latency).
        assert!(
            moves.iter().all(|m| m.1 >= 0.1 - 1e-9 && m.1 < 0.14),
            "{moves:?}"
        );
    }
}
