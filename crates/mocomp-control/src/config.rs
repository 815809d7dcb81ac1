//! The loop's parameters, with their defaults and units. [`LoopParams`] is what a configuration
//! file sets (section `[loop]` of `mocomp run`'s TOML); every field has a default, unknown keys
//! are rejected and [`LoopParams::validate`] names the key of any value out of range.

use crate::geometry::{CoilModel, HeadModel};
use crate::predict::PredictorConfig;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_robot::ServoParams;
use serde::{Deserialize, Serialize};

/// A parameter out of its range, named by its key.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{key} = {value}: {problem}")]
pub struct ParamError {
    /// The key, as in the configuration file.
    pub key: &'static str,
    /// The value given.
    pub value: f64,
    /// What is wrong with it.
    pub problem: &'static str,
}

/// The loop's scalar parameters (SI units: the unit is in each name).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopParams {
    /// Predict the head pose to the time the command acts (else use the newest sample as is,
    /// like the seed paper).
    pub predict: bool,
    /// Keep this far inside every joint limit, rad. [0.05]
    pub joint_margin_rad: f64,
    /// Fraction of each joint's maximum speed the loop may command. [0.75] (0.5 left a UR3
    /// following a 29°/s turn at its elbow's limit: issue 33's irregular trace)
    pub speed_fraction: f64,
    /// Joint acceleration limit of the command, rad/s². [120] The command's, not the arm's: UR
    /// publishes no joint acceleration limit (its arms are limited by torque; ur_rtde checks
    /// 40 on the acceleration argument its servoJ takes and the controller ignores), and the
    /// simulated controller's servo accelerates at most 40. The servo follows the command
    /// `lookahead` behind; a command that closes a corrected prediction's jump faster than the
    /// arm can is a setpoint the arm follows at its own limit sooner (each setpoint still within
    /// the joint's maximum speed of every one the controller may hold). The patient studies'
    /// fast nods need about 20 on a UR3 following at 3 mm; an onset needs more (issue 33: 25
    /// left the irregular trace's execution share at 0.57 mm; its excess over the oracle, mean
    /// of seeds 1–4, with the lead below: 0.508 mm RMS at 40, 0.476 at 50, 0.460 at 60, 0.444
    /// at 80, where the closed-loop test's still head on a UR3e goes from 0.174 to 0.189 mm;
    /// the fast nods' 0.250 at 40, 0.244 at 60). Weighed by the dose (`weigh_by_dose`), what
    /// the budget withholds is what the dose misses at an onset: the irregular trace's dose
    /// error p95 (D70, seeds 1–4) 1.605 % at 60, 1.497 at 90, 1.453 at 120 (lead 0.15), 1.470 at
    /// 120 with the lead at 0.1, its d RMS 0.646 → 0.620 mm, and the closed-loop still head
    /// 0.168 → 0.177 mm; so 120 with the lead at 0.1.
    pub max_joint_accel_rad_s2: f64,
    /// TCP (coil) speed limit, m/s. [0.25]
    pub max_tcp_speed_m_s: f64,
    /// Where the acceleration and speed limits cannot grant every joint its wish, give up what
    /// costs the dose at the target least (the coil's slide along the scalp and its turn about
    /// its axis) before its lift and tilt: the limited step nearest the wished one weighed by
    /// the dose's sensitivities (`compensator::priorities`); false: clamp each joint on its own.
    /// [true]
    pub weigh_by_dose: bool,
    /// How much of the servo's lag behind the command's catch-up the setpoint sent leads by, in
    /// [0, 1]. The horizon already carries the servo's lag behind the predicted goal's own
    /// motion; what the command does besides (closing the jump a new sample makes in the
    /// prediction) the servo follows `lookahead·c + ċ/gain` behind (`c`: the command's speed
    /// relative to the goal's, per joint; servoj's law as modelled, `q̈ = gain·(q_set − q −
    /// lookahead·q̇)`), and the setpoint leads the command by this fraction of it. The full
    /// lag follows each sample's jump and rings (the demo's irregular trace: excess over the
    /// oracle 0.55 → 0.91 mm RMS); 0.3 closed the jumps sooner without it at a budget of 40
    /// (0.55 → 0.48, the fast nods 0.23 → 0.22). The kick at a catch-up's start and end grows
    /// with the command's acceleration budget: at 60, 0.3 took the closed-loop test's still
    /// head on a UR3e from 0.172 to 0.250 mm RMS (0.186 at 0.2, 0.174 at 0.15), where the
    /// irregular trace's excess (seeds 1–4) is 0.442 at 0.3, 0.450 at 0.2, 0.460 at 0.15 and
    /// 0.472 at 0.1. At the budget of 120 (for the dose, above) the kick grows again: the still
    /// head 0.200 mm at 0.15 and 0.177 at 0.1, the irregular trace's dose p95 1.453 and 1.470 %.
    /// 0: the setpoint is the command. [0.1]
    pub catch_up_lead: f64,
    /// Beyond this deviation of the flange from its goal (m) the loop plans a path instead of
    /// servoing straight. [0.02]
    pub servo_deviation_m: f64,
    /// Beyond this rotation from the goal (rad) the loop plans a path. [0.7, about 40°]
    pub plan_rotation_rad: f64,
    /// Distance from the head the planned path keeps while travelling around it, m. [0.05]
    pub shell_distance_m: f64,
    /// Coil speed along a planned path, m/s (rotation: 0.1 m per rad). [0.05]
    pub approach_speed_m_s: f64,
    /// Acceleration along a planned path, m/s². [0.2]
    pub approach_accel_m_s2: f64,
    /// The path waits while the command lags its point by more than this, m. [0.005]
    pub path_lag_m: f64,
    /// A coil farther than this from the head, or one whose shell path has no solution on its
    /// IK branch (a branch change), first moves in joint space (as `movej` would) to its goal's
    /// approach axis this far back from the goal, on the branch the goal is tracked on; the shell
    /// path takes over from there, m. [0.1]
    pub transit_distance_m: f64,
    /// The largest joint's speed on that joint-space move, rad/s. [0.6]
    pub transit_speed_rad_s: f64,
    /// Its acceleration, rad/s². [1.2]
    pub transit_accel_rad_s2: f64,
    /// Tracker sample older than this (s, by its acquisition time) is late: 75 ms lets a 60 Hz
    /// tracker with 20 ms latency lose one sample. Beyond it the loop coasts on the prediction
    /// for `coast_s`, then holds. [0.075]
    pub tracker_stale_s: f64,
    /// How long a dropout (late or invalid samples) is coasted on the prediction past
    /// `tracker_stale_s`, with a standoff that grows with the prediction's uncertainty, s.
    /// [0.15]
    pub coast_s: f64,
    /// The safety filter's margin: the coil keeps `coil_min_distance_m` plus this many standard
    /// deviations of the predicted head (at the coil, at the time the command acts). The
    /// filter's σ is conservative (mean normalised error 0.5 at 80 ms in the prediction study),
    /// so 2 of them cover more than 2 real ones. [2]
    pub safety_sigmas: f64,
    /// How far the coil backs off along its approach axis while retreating (head too fast, head
    /// into the coil), m. [0.03]
    pub retreat_distance_m: f64,
    /// How fast a standoff shrinks again once no longer needed (the coil coming back in along
    /// its axis), m/s. [0.25]
    pub standoff_return_m_s: f64,
    /// The coil's speed limit while it retreats, m/s: moving away from the head may be faster than moving otherwise, so a head
    /// faster than `max_tcp_speed_m_s` never catches it. [0.5]
    pub retreat_tcp_speed_m_s: f64,
    /// A retreat ends when its reason has been clear this long, s (shorter than a hold's
    /// `resume_after_s`: the coil is following the head already, only further out). [0.1]
    pub retreat_resume_s: f64,
    /// The largest standoff the filter may ask for, m. [0.1]
    pub max_standoff_m: f64,
    /// This many identical consecutive samples mean a frozen tracker stream. [20]
    pub frozen_samples: u32,
    /// A sample implying a head speed above this (m/s) is an outlier and ignored. [1.0]
    pub outlier_speed_m_s: f64,
    /// A sample implying an angular speed above this (rad/s) is an outlier. [10]
    pub outlier_speed_rad_s: f64,
    /// Head speed above this (m/s) holds the robot instead of chasing. [0.15]
    pub max_head_speed_m_s: f64,
    /// Head angular speed above this (rad/s) holds the robot. [1.2, about 70°/s]
    pub max_head_speed_rad_s: f64,
    /// A fault must have been clear this long before tracking resumes, s. [0.2]
    pub resume_after_s: f64,
    /// Robot state received longer ago than this is stale and stops the robot, s. A state a
    /// few periods late (a busy PC, a delayed packet) is not: the loop goes on with the newest
    /// one and steps by the controller time that really passed. 30 ms is 15 e-Series or about
    /// 4 CB3 periods, and below the control program's 50 ms watchdog, so the loop stops the
    /// robot itself before the controller would. [0.03]
    pub robot_stale_s: f64,
    /// A stale robot state that lasts this long needs the operator's resume (a re-arm) before
    /// the loop moves the arm again, as every fault the controller itself reports does: past
    /// the control program's 50 ms watchdog the controller has stopped the arm on its own, and
    /// what the patient did meanwhile is unknown. A shorter gap, with the program still
    /// running, is the loop's own stop, and it resumes by itself, by a path from where the arm
    /// is. [0.25]
    pub robot_rearm_after_s: f64,
    /// Singularity margin below which the loop slows down (see `Singularity::margin`). [0.1]
    pub singularity_slow: f64,
    /// Singularity margin below which the loop holds. [0.02]
    pub singularity_hold: f64,
    /// Deceleration used when the robot is stopped by the loop, rad/s². [4]
    pub stop_decel_rad_s2: f64,
    /// The coil's closest allowed distance to the scalp, m: 0 lets it touch, never enter.
    /// A goal closer than this is refused. [0]
    pub coil_min_distance_m: f64,
    /// Below `coil_min_distance_m`, the depth the coil may still move within (the scalp's and
    /// hair's give), m: a head that moves into a lagging coil must not lock it in place. Deeper
    /// than this, motions that go deeper are refused. [0.002]
    pub coil_contact_tolerance_m: f64,
    /// Closest distance any arm link may come to the head, m. [0.01]
    pub link_clearance_m: f64,
    /// Link capsule radius, m. [0.045]
    pub link_radius_m: f64,
    /// Within `approach_zone_m` of the head the coil must stay within this of its approach axis
    /// (the goal's z axis), m. [0.01]
    pub approach_tolerance_m: f64,
    /// Thickness of the zone around the head where the approach rule applies, m. [0.03]
    pub approach_zone_m: f64,
    /// Read the wrench the robot reports (an e-Series' flange sensor, a CB3's estimate) and
    /// apply the force rules (see [`crate::force`]). [false]
    pub force_sensing: bool,
    /// Time constant of the low-pass filter on the wrench, s (0: none). [0.01]
    pub force_filter_s: f64,
    /// A reading that has not changed for this long (controller time) is stale: a live sensor's
    /// noise changes it every sample, s. [0.05]
    pub force_stale_s: f64,
    /// Above this force the coil retreats at once, N. [30] (InVesalius' safety threshold; the
    /// Lübeck FTA layer stops under 30 N in the TMS speed range)
    pub max_contact_force_n: f64,
    /// Above this force for longer than `contact_warning_s` the coil retreats, N. [15]
    pub contact_warning_force_n: f64,
    /// How long the force may stay above `contact_warning_force_n`, s. [0.5] (InVesalius: 0.5 s)
    pub contact_warning_s: f64,
    /// A retreat for a force rule ends when the rule has been clear this long, s. [1]
    pub contact_resume_s: f64,
    /// Hold a light contact along the coil's axis (admittance on the axial force) instead of the
    /// goal's fixed standoff; needs `force_sensing`. [false]
    pub contact_mode: bool,
    /// The contact force contact mode holds, N. [3]
    pub contact_force_n: f64,
    /// The admittance's virtual damping: a force error of 1 N moves the coil 1/this m/s, N·s/m.
    /// [500] (stable on scalp up to about 20 N/mm with the servo's lag; see [`crate::force`])
    pub contact_damping_n_s_m: f64,
    /// The admittance's largest speed along the axis, m/s. [0.01]
    pub contact_speed_m_s: f64,
    /// The deepest contact mode may press the coil below the head model's surface, m (the
    /// model's error and the scalp's give). [0.01]
    pub contact_max_press_m: f64,
}

impl Default for LoopParams {
    fn default() -> Self {
        Self {
            predict: true,
            joint_margin_rad: 0.05,
            speed_fraction: 0.75,
            max_joint_accel_rad_s2: 120.0,
            max_tcp_speed_m_s: 0.25,
            weigh_by_dose: true,
            catch_up_lead: 0.1,
            servo_deviation_m: 0.02,
            plan_rotation_rad: 0.7,
            shell_distance_m: 0.05,
            approach_speed_m_s: 0.05,
            approach_accel_m_s2: 0.2,
            path_lag_m: 0.005,
            transit_distance_m: 0.1,
            transit_speed_rad_s: 0.6,
            transit_accel_rad_s2: 1.2,
            tracker_stale_s: 0.075,
            coast_s: 0.15,
            safety_sigmas: 2.0,
            retreat_distance_m: 0.03,
            standoff_return_m_s: 0.25,
            retreat_resume_s: 0.1,
            retreat_tcp_speed_m_s: 0.5,
            max_standoff_m: 0.1,
            frozen_samples: 20,
            outlier_speed_m_s: 1.0,
            outlier_speed_rad_s: 10.0,
            max_head_speed_m_s: 0.15,
            max_head_speed_rad_s: 1.2,
            resume_after_s: 0.2,
            robot_stale_s: 0.03,
            robot_rearm_after_s: 0.25,
            singularity_slow: 0.1,
            singularity_hold: 0.02,
            stop_decel_rad_s2: 4.0,
            coil_min_distance_m: 0.0,
            coil_contact_tolerance_m: 0.002,
            link_clearance_m: 0.01,
            link_radius_m: 0.045,
            approach_tolerance_m: 0.01,
            approach_zone_m: 0.03,
            force_sensing: false,
            force_filter_s: 0.01,
            force_stale_s: 0.05,
            max_contact_force_n: 30.0,
            contact_warning_force_n: 15.0,
            contact_warning_s: 0.5,
            contact_resume_s: 1.0,
            contact_mode: false,
            contact_force_n: 3.0,
            contact_damping_n_s_m: 500.0,
            contact_speed_m_s: 0.01,
            contact_max_press_m: 0.01,
        }
    }
}

impl LoopParams {
    /// The closest a goal may put the coil to the head model, m: `coil_min_distance_m`, or in
    /// contact mode, where a taught goal touches the scalp, down to the scalp's give
    /// (`-coil_contact_tolerance_m`).
    pub fn goal_min_distance_m(&self) -> f64 {
        if self.contact_mode {
            self.coil_min_distance_m.min(-self.coil_contact_tolerance_m)
        } else {
            self.coil_min_distance_m
        }
    }

    /// Checks every value's range and the relations between them; the error names the first
    /// key out of range, in the order below.
    pub fn validate(&self) -> Result<(), ParamError> {
        use Bound::{NonNegative as Z, Positive as P};
        ranges(&[("joint_margin_rad", self.joint_margin_rad, Z)])?;
        let fraction = self.speed_fraction;
        relation(
            fraction > 0.0 && fraction <= 1.0,
            ("speed_fraction", fraction),
            "must be in (0, 1]",
        )?;
        relation(
            (0.0..=1.0).contains(&self.catch_up_lead),
            ("catch_up_lead", self.catch_up_lead),
            "must be in [0, 1]",
        )?;
        ranges(&[
            ("max_joint_accel_rad_s2", self.max_joint_accel_rad_s2, P),
            ("max_tcp_speed_m_s", self.max_tcp_speed_m_s, P),
            ("servo_deviation_m", self.servo_deviation_m, P),
            ("plan_rotation_rad", self.plan_rotation_rad, P),
            ("shell_distance_m", self.shell_distance_m, P),
            ("approach_speed_m_s", self.approach_speed_m_s, P),
            ("approach_accel_m_s2", self.approach_accel_m_s2, P),
            ("path_lag_m", self.path_lag_m, P),
            ("transit_distance_m", self.transit_distance_m, P),
            ("transit_speed_rad_s", self.transit_speed_rad_s, P),
            ("transit_accel_rad_s2", self.transit_accel_rad_s2, P),
            ("tracker_stale_s", self.tracker_stale_s, P),
            ("coast_s", self.coast_s, Z),
            ("safety_sigmas", self.safety_sigmas, Z),
            ("retreat_distance_m", self.retreat_distance_m, Z),
            ("standoff_return_m_s", self.standoff_return_m_s, P),
            ("max_standoff_m", self.max_standoff_m, P),
            ("retreat_resume_s", self.retreat_resume_s, P),
            ("retreat_tcp_speed_m_s", self.retreat_tcp_speed_m_s, P),
        ])?;
        relation(
            self.retreat_distance_m <= self.max_standoff_m,
            ("retreat_distance_m", self.retreat_distance_m),
            "must be at most max_standoff_m",
        )?;
        relation(
            self.frozen_samples >= 2,
            ("frozen_samples", f64::from(self.frozen_samples)),
            "must be at least 2",
        )?;
        ranges(&[
            ("outlier_speed_m_s", self.outlier_speed_m_s, P),
            ("outlier_speed_rad_s", self.outlier_speed_rad_s, P),
            ("max_head_speed_m_s", self.max_head_speed_m_s, P),
            ("max_head_speed_rad_s", self.max_head_speed_rad_s, P),
            ("resume_after_s", self.resume_after_s, P),
            ("robot_stale_s", self.robot_stale_s, P),
        ])?;
        relation(
            self.robot_rearm_after_s.is_finite() && self.robot_rearm_after_s >= self.robot_stale_s,
            ("robot_rearm_after_s", self.robot_rearm_after_s),
            "must be finite and at least robot_stale_s",
        )?;
        ranges(&[
            ("singularity_slow", self.singularity_slow, P),
            ("singularity_hold", self.singularity_hold, Z),
            ("stop_decel_rad_s2", self.stop_decel_rad_s2, P),
            ("coil_min_distance_m", self.coil_min_distance_m, Z),
            ("coil_contact_tolerance_m", self.coil_contact_tolerance_m, Z),
            ("link_clearance_m", self.link_clearance_m, Z),
            ("link_radius_m", self.link_radius_m, P),
            ("approach_tolerance_m", self.approach_tolerance_m, P),
            ("approach_zone_m", self.approach_zone_m, P),
        ])?;
        self.speed_relations()?;
        ranges(&[
            ("force_filter_s", self.force_filter_s, Z),
            ("force_stale_s", self.force_stale_s, P),
            ("max_contact_force_n", self.max_contact_force_n, P),
            ("contact_warning_force_n", self.contact_warning_force_n, P),
            ("contact_warning_s", self.contact_warning_s, P),
            ("contact_resume_s", self.contact_resume_s, P),
            ("contact_force_n", self.contact_force_n, P),
            ("contact_damping_n_s_m", self.contact_damping_n_s_m, P),
            ("contact_speed_m_s", self.contact_speed_m_s, P),
            ("contact_max_press_m", self.contact_max_press_m, P),
        ])?;
        self.contact_relations()?;
        self.path_relations()
    }

    /// A slowdown before the hold near a singularity, and an outlier faster than any head the
    /// loop follows (the values are finite by now).
    fn speed_relations(&self) -> Result<(), ParamError> {
        relation(
            self.singularity_hold < self.singularity_slow,
            ("singularity_hold", self.singularity_hold),
            "must be below singularity_slow",
        )?;
        relation(
            self.outlier_speed_m_s > self.max_head_speed_m_s,
            ("outlier_speed_m_s", self.outlier_speed_m_s),
            "must be above max_head_speed_m_s",
        )?;
        relation(
            self.outlier_speed_rad_s > self.max_head_speed_rad_s,
            ("outlier_speed_rad_s", self.outlier_speed_rad_s),
            "must be above max_head_speed_rad_s",
        )
    }

    /// The force thresholds in order, and contact mode only on a measured force.
    fn contact_relations(&self) -> Result<(), ParamError> {
        relation(
            self.contact_warning_force_n < self.max_contact_force_n,
            ("contact_warning_force_n", self.contact_warning_force_n),
            "must be below max_contact_force_n",
        )?;
        relation(
            self.contact_force_n < self.contact_warning_force_n,
            ("contact_force_n", self.contact_force_n),
            "must be below contact_warning_force_n (a set force the rules retreat from cannot be held)",
        )?;
        relation(
            !self.contact_mode || self.force_sensing,
            ("contact_mode", 1.0),
            "needs force_sensing = true (contact is held on the measured force)",
        )
    }

    /// The approach zone inside the shell, and a transit that ends outside the shell.
    fn path_relations(&self) -> Result<(), ParamError> {
        relation(
            self.shell_distance_m > self.approach_zone_m,
            ("shell_distance_m", self.shell_distance_m),
            "must be above approach_zone_m (the shell is outside the approach zone)",
        )?;
        relation(
            self.transit_distance_m >= self.shell_distance_m,
            ("transit_distance_m", self.transit_distance_m),
            "must be at least shell_distance_m (a joint-space move ends outside the shell)",
        )
    }
}

/// A parameter's range.
#[derive(Debug, Clone, Copy)]
enum Bound {
    /// Finite and > 0.
    Positive,
    /// Finite and ≥ 0.
    NonNegative,
}

/// The first of `keys` (name, value, range) out of its range.
fn ranges(keys: &[(&'static str, f64, Bound)]) -> Result<(), ParamError> {
    for &(key, value, bound) in keys {
        let (ok, problem) = match bound {
            Bound::Positive => (value.is_finite() && value > 0.0, "must be finite and > 0"),
            Bound::NonNegative => (value.is_finite() && value >= 0.0, "must be finite and ≥ 0"),
        };
        relation(ok, (key, value), problem)?;
    }
    Ok(())
}

/// `Ok` when `holds`, else the error for `key` with its value.
fn relation(
    holds: bool,
    (key, value): (&'static str, f64),
    problem: &'static str,
) -> Result<(), ParamError> {
    if holds {
        Ok(())
    } else {
        Err(ParamError {
            key,
            value,
            problem,
        })
    }
}

/// Everything the compensation loop needs besides the robot and the tracker.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopConfig {
    /// `Y`: base_from_tracker (from calibration).
    pub base_from_tracker: Isometry3<f64>,
    /// `X` for the coil: flange_from_coil (the coil's mounting on the flange).
    pub flange_from_coil: Isometry3<f64>,
    /// The goal: head_from_coil (taught or configured).
    pub head_from_coil_goal: Isometry3<f64>,
    /// servoj parameters (time = the controller period).
    pub servo: ServoParams,
    /// The predictor's noise model.
    pub predictor: PredictorConfig,
    /// The head's collision model.
    pub head: HeadModel,
    /// The coil's collision model.
    pub coil: CoilModel,
    /// The scalar parameters.
    pub params: LoopParams,
}

impl LoopConfig {
    /// Defaults around the given frames.
    pub fn new(
        base_from_tracker: Isometry3<f64>,
        flange_from_coil: Isometry3<f64>,
        head_from_coil_goal: Isometry3<f64>,
        period_s: f64,
    ) -> Self {
        Self {
            base_from_tracker,
            flange_from_coil,
            head_from_coil_goal,
            servo: ServoParams {
                time_s: period_s,
                lookahead_s: 0.03,
                gain: 2000.0,
            },
            predictor: PredictorConfig::default(),
            head: HeadModel::adult(),
            coil: CoilModel::cylinder(0.04, 0.03),
            params: LoopParams::default(),
        }
    }
}
