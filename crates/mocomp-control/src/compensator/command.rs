//! The command side of the cycle: the joint setpoint and its speed, the controller time it is
//! stepped by, the rate and acceleration limits ([`CommandState::limit`]), and the estimate of
//! how long a command takes to reach the controller ([`DelayEstimator`]). Pure: the robot's
//! state comes in as a value, nothing is sent from here.

use super::held::HeldSetpoints;
use super::in_flight::InFlight;
use crate::config::LoopParams;
use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::Arm;
use mocomp_robot::RobotState;

/// Commands remembered for the delay estimate.
const ACK_RING: usize = 64;

/// A joint's catch-up of about this speed (rad/s) is mostly the prediction's noise: a tracker
/// sample's 0.1 mm and 1 mrad carried over the horizon move the goal a milliradian or two, which
/// the command closes within a few cycles. Leading it would make the arm follow that noise (the
/// still head of the closed-loop test: 0.17 → 0.22 mm RMS on a UR3e); a catch-up `c` is led by
/// its share `c² / (c² + this²)`.
const CATCH_UP_NOISE_RAD_S: f64 = 0.1;

/// The setpoint the loop commands and how it moves.
#[derive(Debug, Clone)]
pub(super) struct CommandState {
    /// The joints last commanded.
    pub(super) q: [f64; 6],
    /// Their speed, rad/s.
    pub(super) v: [f64; 6],
    /// `q` is a setpoint to go on from (false: start from where the arm is).
    pub(super) have: bool,
    /// The previous cycle's target joints (for the target's speed).
    pub(super) last_desired: Option<[f64; 6]>,
    /// The controller time of the state the previous command answered (NaN before the first).
    pub(super) last_controller_s: f64,
    /// The controller time between the previous command and this one, s: the time the command
    /// is stepped by.
    pub(super) dt: f64,
    /// A servo command has been sent (`q` is a setpoint the controller may hold).
    pub(super) servo_sent: bool,
    /// Whether this cycle's command gives way to the head (retreating): its speed limit is
    /// `retreat_tcp_speed_m_s`. (Not for the filter's small corrections: at that speed they
    /// overshoot and the servo's lag brings the coil back in.)
    pub(super) giving_way: bool,
    /// Send → acknowledged in the robot's state.
    pub(super) delay: DelayEstimator,
    /// This cycle's target speed along the head's prediction (rad/s), when the target is the
    /// goal and the prediction says it; `None`: from the target's last two values.
    pub(super) target_speed: Option<[f64; 6]>,
    /// The servo setpoint's lead over `q` last sent, rad ([`Self::setpoint`]).
    pub(super) lead: [f64; 6],
    /// The command's speed relative to the target's at the last setpoint (its catch-up), rad/s;
    /// `None` after a start, when there is none to take the change from.
    pub(super) catch_up: Option<[f64; 6]>,
    /// The setpoints the controller may hold when the next lands: each setpoint stays within
    /// the joint's maximum speed of all of them ([`HeldSetpoints`]).
    pub(super) held: HeldSetpoints,
}

/// The command state before this cycle's limits ran: a correction (the safety filter, a
/// refusal) starts again from it, so it is limited like any command.
#[derive(Debug, Clone, Copy)]
pub(super) struct Saved {
    /// The previous command's joints.
    pub(super) q: [f64; 6],
    v: [f64; 6],
    last_desired: Option<[f64; 6]>,
}

impl CommandState {
    /// No command yet, at the robot's `period_s`.
    pub(super) fn new(period_s: f64) -> Self {
        Self {
            q: [0.0; 6],
            v: [0.0; 6],
            have: false,
            last_desired: None,
            last_controller_s: f64::NAN,
            dt: period_s,
            servo_sent: false,
            giving_way: false,
            delay: DelayEstimator::new(period_s),
            target_speed: None,
            lead: [0.0; 6],
            catch_up: None,
            held: HeldSetpoints::new(),
        }
    }

    /// This cycle's controller time step from the robot's `state`, and without a command the
    /// command's start from it.
    ///
    /// Step by the controller's time, not the loop's: what matters is how long the controller
    /// held the previous setpoint. Several states that arrive together give one longer step; a
    /// cycle on the same state (woken without a new one) gives none.
    pub(super) fn step_time(&mut self, state: &RobotState, period: f64, robot_stale_s: f64) {
        self.dt = if self.last_controller_s.is_finite() {
            let raw = state.controller_s - self.last_controller_s;
            // The controller's clock advances in whole periods: the difference of two large
            // times carries rounding that depends on how long the controller has been up, which
            // would make the same run differ in its last bits from one start to the next.
            let periods = (raw / period).round();
            let dt = if (raw - periods * period).abs() < 1e-6 {
                periods * period
            } else {
                raw
            };
            dt.clamp(0.0, robot_stale_s)
        } else {
            period
        };
        self.last_controller_s = state.controller_s;
        if !self.have {
            if state.program_mode == mocomp_robot::mode::SERVO && self.servo_sent {
                // The controller still servoes to the last setpoint (a stop that never reached
                // it): it judges the next one against that, so the command goes on from there,
                // standing (its lead, too, shrinks from there within the setpoint's speed).
                self.v = [0.0; 6];
            } else {
                self.lead = [0.0; 6];
                self.held.clear();
                // Start (or come back after a stop) from where the arm is and how it moves, so
                // the first command continues its motion instead of jerking it to a halt.
                self.q = state.actual_q;
                self.v = std::array::from_fn(|j| {
                    let v = state.actual_qd[j];
                    if v.is_finite() { v } else { 0.0 }
                });
            }
            self.dt = period;
            self.have = true;
            self.last_desired = None;
            self.catch_up = None;
        }
    }

    /// The state a correction starts again from.
    pub(super) fn save(&self) -> Saved {
        Saved {
            q: self.q,
            v: self.v,
            last_desired: self.last_desired,
        }
    }

    /// Back to the state before this cycle's limits ran.
    pub(super) fn restore(&mut self, saved: Saved) {
        (self.q, self.v, self.last_desired) = (saved.q, saved.v, saved.last_desired);
    }

    /// A hold's target: the last command, standing. Its speed is zero, so the limits
    /// decelerate the arm to standstill on it; a target taken as moving at the command's own
    /// speed (the feed-forward of a followed target) would keep the arm going forever.
    pub(super) fn stand_still(&mut self) -> [f64; 6] {
        self.last_desired = None;
        self.target_speed = None;
        self.q
    }

    /// Rate- and acceleration-limits the command towards `desired`, joint by joint, so that each
    /// joint can still stop at `desired` within its acceleration, relative to the target's own
    /// motion: a moving target is followed at its speed (feed-forward), not approached as if it
    /// stood still, which would lag it by the braking distance. The target's speed is its speed
    /// along this cycle's prediction when known (`self.target_speed`): a new tracker sample
    /// moves the whole predicted path, and that jump is an error to close within the limits, not
    /// a speed to keep (taken as one, the arm overshoots at onsets: on the demo's irregular
    /// trace the worst moment went from 8.4 to 6.0 mm). Else it is over the controller time
    /// since the previous command (`self.dt`). The step itself is never longer than one
    /// controller period's: the controller judges a setpoint against its previous one,
    /// which it may have taken only one period ago however long this state took to come (a
    /// controller that stalled and caught up, a network that held the previous command back),
    /// so after any gap the command goes on from the last setpoint within the per-cycle limit
    /// (URControl's C204A3) and makes up the lost time over the following cycles. A cycle with
    /// no controller time passed moves nothing. Where a joint's wish is beyond its limits and
    /// `weigh_by_dose` gives the coil's mounting, the step is the one within the same limits
    /// whose coil motion loses the least dose against the wished one
    /// ([`super::priorities`]), not each joint clamped on its own.
    pub(super) fn limit(
        &mut self,
        arm: &Arm,
        p: &LoopParams,
        period: f64,
        desired: &[f64; 6],
        speed_fraction: f64,
        weigh_by_dose: Option<&Isometry3<f64>>,
    ) -> [f64; 6] {
        if self.dt <= 0.0 {
            return self.q;
        }
        let target_dt = self.dt;
        let dt = self.dt.min(period);
        let a = p.max_joint_accel_rad_s2;
        let mut q = self.q;
        let mut v = self.v;
        let previous = self.last_desired.replace(*desired);
        // Each joint's wished speed and the speeds this cycle's limits allow it.
        let mut wish = [0.0; 6];
        let mut lo = [0.0; 6];
        let mut hi = [0.0; 6];
        for j in 0..6 {
            let vmax = arm.spec().max_speed[j] * speed_fraction;
            // The target's speed: along the prediction, else from its last two values; a jump
            // (a new mode, a retreat) is not a speed to keep.
            let v_target = self
                .target_speed
                .map(|v| v[j])
                .or_else(|| previous.map(|p| (desired[j] - p[j]) / target_dt))
                .filter(|v| v.abs() <= vmax)
                .unwrap_or(0.0);
            let delta = desired[j] - self.q[j];
            // Largest speed relative to the target from which the joint can still stop on it in
            // whole cycles of deceleration a·dt each: n·a·dt with a·dt²·n(n+1)/2 ≤ |delta| (the
            // continuous √(2a|delta|) overshoots by up to a cycle and chatters around a still
            // target).
            let adt2 = a * dt * dt;
            let n = 0.5 * ((1.0 + 8.0 * delta.abs() / adt2).sqrt() - 1.0);
            let v_stop = n * a * dt;
            wish[j] = v_target + (delta / dt - v_target).clamp(-v_stop, v_stop);
            // The speed limit, then the acceleration's: where the two do not meet (a joint
            // faster than a lowered speed fraction) the acceleration wins, slowing it at most.
            let (slow, fast) = (self.v[j] - a * dt, self.v[j] + a * dt);
            lo[j] = (-vmax).clamp(slow, fast);
            hi[j] = vmax.clamp(slow, fast);
            v[j] = wish[j].clamp(lo[j], hi[j]);
        }
        let tcp_limit = if self.giving_way {
            p.max_tcp_speed_m_s.max(p.retreat_tcp_speed_m_s)
        } else {
            p.max_tcp_speed_m_s
        };
        let p0 = arm.fk(&self.q).translation.vector;
        let tcp_speed = |v: &[f64; 6]| {
            let q1: [f64; 6] = std::array::from_fn(|j| self.q[j] + v[j] * dt);
            (arm.fk(&q1).translation.vector - p0).norm() / dt
        };
        if let Some(flange_from_coil) = weigh_by_dose
            && v != wish
        {
            let form = super::priorities::dose_form(arm, &self.q, flange_from_coil);
            v = super::priorities::nearest_in_box(&form, &wish, &lo, &hi);
            // Too fast for the coil: the wish slowed until the step is not, within the same
            // limits (scaling the step itself, below, could take a joint out of them).
            if tcp_speed(&v) > tcp_limit
                && let Some(slower) =
                    super::priorities::slowed_in_box(&form, &wish, &lo, &hi, |v| {
                        tcp_speed(v) <= tcp_limit
                    })
            {
                v = slower;
            }
        }
        for j in 0..6 {
            q[j] = self.q[j] + v[j] * dt;
        }
        // The coil's speed limit, on the whole step (the last word: over the acceleration's
        // where both cannot hold).
        let speed = tcp_speed(&v);
        if speed > tcp_limit {
            let k = tcp_limit / speed;
            for j in 0..6 {
                v[j] *= k;
                q[j] = self.q[j] + v[j] * dt;
            }
        }
        // The setpoint this makes (with the lead as it is) within reach of every setpoint the
        // controller may hold.
        for j in 0..6 {
            let (lo, hi) = self.held_range(arm, j, period);
            let within = q[j].max(lo - self.lead[j]).min(hi - self.lead[j]);
            if within != q[j] {
                q[j] = within;
                v[j] = (q[j] - self.q[j]) / dt;
            }
        }
        self.v = v;
        q
    }

    /// The range joint `j`'s next setpoint must stay in ([`HeldSetpoints::range`]), at the
    /// joint's maximum speed.
    fn held_range(&self, arm: &Arm, j: usize, period: f64) -> (f64, f64) {
        let now = if self.last_controller_s.is_finite() {
            self.last_controller_s
        } else {
            0.0
        };
        self.held.range(j, now, period, arm.spec().max_speed[j])
    }

    /// The servo setpoint for this cycle's command `self.q` (already limited): the command plus
    /// a lead of `lead_fraction` times the servo's lag behind the command's catch-up (a
    /// catch-up the size of the prediction's noise less: [`CATCH_UP_NOISE_RAD_S`]), when the
    /// command follows the goal (`following`, and the target's speed along the prediction
    /// known); otherwise the lead shrinks to nothing.
    ///
    /// The horizon already aims the command ahead by the servo's lag behind the goal's own
    /// motion; the catch-up `c = v − v_target` (the command closing the jump a new sample made
    /// in the prediction) it does not, and servoj (`q̈ = gain·(q_set − q − lookahead·q̇)`)
    /// follows it `lookahead·c + ċ/gain` behind. The lead is bounded by the servo's lag at the
    /// command's top speed, and changes so that it never makes the setpoint's own step longer
    /// than the command's, or than the command's ceiling (`speed_fraction` of the joint's
    /// maximum) when that is longer; and the setpoint stays within reach of every setpoint the
    /// controller may hold ([`HeldSetpoints`]: steps that land together are no jump). The first
    /// setpoint after a start has none (no catch-up yet to take its change from); a cycle with
    /// no controller time passed changes nothing.
    pub(super) fn setpoint(
        &mut self,
        arm: &Arm,
        servo: (f64, f64),
        period: f64,
        (lead_fraction, speed_fraction): (f64, f64),
        following: bool,
    ) -> [f64; 6] {
        if self.dt <= 0.0 {
            return std::array::from_fn(|j| self.q[j] + self.lead[j]);
        }
        let (lookahead, gain) = servo;
        let dt = self.dt.min(period);
        let catch_up = self
            .target_speed
            .filter(|_| following && lead_fraction > 0.0)
            .map(|vt| std::array::from_fn::<f64, 6, _>(|j| self.v[j] - vt[j]));
        let previous = std::mem::replace(&mut self.catch_up, catch_up);
        std::array::from_fn(|j| {
            let want = match (catch_up, previous) {
                (Some(c), Some(c0)) => {
                    let size = c[j].abs().max(c0[j].abs()).powi(2);
                    let share = size / (size + CATCH_UP_NOISE_RAD_S.powi(2));
                    share * lead_fraction * (lookahead * c[j] + (c[j] - c0[j]) / (gain * dt))
                }
                _ => 0.0,
            };
            let vmax = arm.spec().max_speed[j] * speed_fraction;
            let bound = lookahead * vmax;
            // The setpoint's step is v·dt plus the lead's change: within ±vmax·dt, or no longer
            // than the command's own step where that is longer.
            let lo = (self.lead[j] - (vmax + self.v[j]) * dt).min(self.lead[j]);
            let hi = (self.lead[j] + (vmax - self.v[j]) * dt).max(self.lead[j]);
            // max/min, not clamp: a non-finite bound must not panic the loop.
            let lead = want.max(-bound).min(bound).max(lo).min(hi);
            let (lo, hi) = self.held_range(arm, j, period);
            self.lead[j] = (self.q[j] + lead).max(lo).min(hi) - self.q[j];
            self.q[j] + self.lead[j]
        })
    }
}

/// The command delay (send → acknowledged in the robot's state), averaged: commands sent are
/// remembered by sequence number ([`InFlight`]), and each acknowledgement found in a state
/// moves the estimate.
#[derive(Debug, Clone)]
pub(super) struct DelayEstimator {
    estimate: f64,
    /// Each command in flight, with the loop time it was sent.
    sent: InFlight<f64, ACK_RING>,
}

impl DelayEstimator {
    /// An estimate of one period before anything is measured.
    pub(super) fn new(period_s: f64) -> Self {
        Self {
            estimate: period_s,
            sent: InFlight::new(0.0),
        }
    }

    /// The estimate, s.
    pub(super) fn estimate(&self) -> f64 {
        self.estimate
    }

    /// Command `seq` was sent at loop time `t`.
    pub(super) fn note(&mut self, seq: i32, t: f64) {
        self.sent.push(seq, t);
    }

    /// A state received at `received_s` acknowledges commands up to `acked`.
    pub(super) fn measure(&mut self, acked: i32, received_s: f64) {
        if let Some(sent) = self.sent.acknowledge(acked) {
            let d = (received_s - sent).max(0.0);
            self.estimate += 0.05 * (d - self.estimate);
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_kin::Model;

    const PERIOD: f64 = 0.002;

    fn state_at(t: f64, q: [f64; 6]) -> RobotState {
        let mut s = RobotState::at_rest(t, q, Isometry3::identity());
        s.controller_s = t;
        s.received_s = t;
        s
    }

    #[test]
    fn the_step_is_the_controllers_time_in_whole_periods_and_bounded() {
        let mut c = CommandState::new(PERIOD);
        let q = [0.1, -1.2, 1.5, -1.8, -1.5, 0.2];
        c.step_time(&state_at(1000.0, q), PERIOD, 0.1);
        // The first command starts where the arm is, stepped by one period.
        assert_eq!(c.q, q);
        assert!(c.have);
        assert_eq!(c.dt, PERIOD);
        // Three periods late: one step of three periods, exactly (no rounding of large times).
        c.step_time(&state_at(1000.0 + 3.0 * PERIOD, q), PERIOD, 0.1);
        assert_eq!(c.dt, 3.0 * PERIOD);
        // The same state again: no time passed, no step.
        c.step_time(&state_at(1000.0 + 3.0 * PERIOD, q), PERIOD, 0.1);
        assert_eq!(c.dt, 0.0);
        // A long gap is bounded by the stale limit.
        c.step_time(&state_at(1010.0, q), PERIOD, 0.1);
        assert_eq!(c.dt, 0.1);
    }

    /// Per joint, and weighed by the dose (the same box, another point in it).
    #[test]
    fn the_limits_bound_speed_and_acceleration_and_a_zero_step_moves_nothing() {
        let coil = Isometry3::translation(0.0, 0.0, 0.12);
        for weigh in [None, Some(&coil)] {
            limits_bound_speed_and_acceleration(weigh);
        }
    }

    fn limits_bound_speed_and_acceleration(weigh: Option<&Isometry3<f64>>) {
        let arm = Arm::new(Model::Ur3e);
        let p = LoopParams::default();
        let mut c = CommandState::new(PERIOD);
        let q0 = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0];
        c.step_time(&state_at(0.0, q0), PERIOD, p.robot_stale_s);
        let far = [0.5, -1.0, 1.2, -1.5, -1.2, 0.4];
        let mut prev_v = [0.0; 6];
        for k in 1..200 {
            c.step_time(&state_at(k as f64 * PERIOD, c.q), PERIOD, p.robot_stale_s);
            let q = c.limit(&arm, &p, PERIOD, &far, 1.0, weigh);
            for j in 0..6 {
                let v = (q[j] - c.q[j]) / PERIOD;
                assert!(
                    v.abs() <= arm.spec().max_speed[j] + 1e-9,
                    "joint {j} speed {v}"
                );
                let dv = (v - prev_v[j]).abs();
                assert!(
                    dv <= p.max_joint_accel_rad_s2 * PERIOD + 1e-9,
                    "joint {j} Δv {dv}"
                );
                prev_v[j] = v;
            }
            let tcp = (arm.fk(&q).translation.vector - arm.fk(&c.q).translation.vector).norm();
            assert!(tcp / PERIOD <= p.max_tcp_speed_m_s + 1e-9);
            c.q = q;
        }
        // A cycle on the same state moves nothing.
        c.step_time(&state_at(199.0 * PERIOD, c.q), PERIOD, p.robot_stale_s);
        assert_eq!(c.limit(&arm, &p, PERIOD, &far, 1.0, weigh), c.q);
    }

    #[test]
    fn a_hold_decelerates_to_standstill_on_the_last_command() {
        let arm = Arm::new(Model::Ur3e);
        let p = LoopParams::default();
        let mut c = CommandState::new(PERIOD);
        let q0 = [0.0, -1.3, 1.6, -1.87, -1.57, 0.0];
        c.step_time(&state_at(0.0, q0), PERIOD, p.robot_stale_s);
        c.v = [0.05; 6];
        for k in 1..400 {
            c.step_time(&state_at(k as f64 * PERIOD, c.q), PERIOD, p.robot_stale_s);
            let hold = c.stand_still();
            c.q = c.limit(&arm, &p, PERIOD, &hold, 1.0, None);
        }
        assert!(c.v.iter().all(|v| v.abs() < 1e-9), "{:?}", c.v);
    }

    /// A CB3's servo period, lookahead and gain, as the demo runs them.
    const CB3: f64 = 0.008;
    const SERVO: (f64, f64) = (0.03, 2000.0);

    /// One controller period of servoj as modelled (the simulated controller's law:
    /// `q̈ = gain·(set − q − lookahead·q̇)` within 40 rad/s², semi-implicit Euler).
    fn servo_step(q: &mut [f64; 6], qd: &mut [f64; 6], set: &[f64; 6]) {
        let (lookahead, gain) = SERVO;
        for j in 0..6 {
            let acc = (gain * (set[j] - q[j] - lookahead * qd[j])).clamp(-40.0, 40.0);
            qd[j] += acc * CB3;
            q[j] += qd[j] * CB3;
        }
    }

    /// The goal moves at 0.5 rad/s on the elbow; at cycle 60 a new sample moves the predicted
    /// path by `jump` rad. The loop aims ahead by the servo's lag, limits, leads by
    /// `lead_fraction` and the modelled servo follows. Returns per cycle the arm against the
    /// goal (the goal's true path, jump included, rad) and the setpoint's lead over the command.
    fn follow_a_jump(lead_fraction: f64, jump: f64) -> Vec<(f64, f64)> {
        let arm = Arm::new(Model::Ur3e);
        let p = LoopParams::default();
        let speed = [0.0, 0.0, 0.5, 0.0, 0.0, 0.0];
        let q0 = [0.0, -1.3, 1.2, -1.87, -1.57, 0.0];
        let goal = |t: f64, k: usize| -> [f64; 6] {
            let extra = if k >= 60 { jump } else { 0.0 };
            std::array::from_fn(|j| q0[j] + speed[j] * t + if j == 2 { extra } else { 0.0 })
        };
        let mut c = CommandState::new(CB3);
        let (mut q, mut qd) = (q0, speed);
        // Aimed ahead by the command's delay (one period) and the servo's lag, as the loop does.
        let ahead = SERVO.0;
        let mut out = Vec::new();
        for k in 0..160 {
            let t = k as f64 * CB3;
            let mut state = state_at(t, q);
            state.actual_qd = qd;
            c.step_time(&state, CB3, p.robot_stale_s);
            c.target_speed = Some(speed);
            c.q = c.limit(&arm, &p, CB3, &goal(t + ahead, k), 1.0, None);
            let set = c.setpoint(&arm, SERVO, CB3, (lead_fraction, 1.0), true);
            servo_step(&mut q, &mut qd, &set);
            out.push((q[2] - goal(t + CB3, k)[2], set[2] - c.q[2]));
        }
        out
    }

    #[test]
    fn a_command_that_follows_the_prediction_is_sent_as_it_is_and_its_catch_up_leads() {
        let lead = follow_a_jump(0.3, 0.005);
        // Settled on the goal's own motion (the horizon carries the servo's lag): no lead.
        for (k, (_, l)) in lead.iter().enumerate().take(60).skip(30) {
            assert!(l.abs() < 1e-9, "cycle {k}: lead {l}");
        }
        // Followed to within 0.1 mrad before the jump.
        assert!(
            lead[30..60].iter().all(|(e, _)| e.abs() < 1e-4),
            "{:?}",
            &lead[30..60]
        );
        // The jump: the command closes it, and the setpoint leads that catch-up.
        assert!(lead[60].1 > 1e-3, "lead {}", lead[60].1);
        // The arm closes the jump sooner than it does without a lead, and goes past the goal by
        // little (the lead only partly makes up the servo's lag).
        let none = follow_a_jump(0.0, 0.005);
        let sq = |r: &[(f64, f64)]| r[60..110].iter().map(|(e, _)| e * e).sum::<f64>();
        assert!(
            sq(&lead) < 0.85 * sq(&none),
            "{} vs {}",
            sq(&lead),
            sq(&none)
        );
        let beyond = lead[60..].iter().map(|(e, _)| *e).fold(f64::MIN, f64::max);
        assert!(beyond < 0.2 * 0.005, "past the goal by {beyond} rad");
        // Settled again: the lead has gone.
        assert!(lead[159].1.abs() < 1e-6, "lead {}", lead[159].1);
    }

    /// Whatever the lead wants, the setpoint's own step is no longer than the command's, or
    /// than the command's ceiling; and the lead never exceeds the servo's lag at that ceiling.
    #[test]
    fn the_setpoints_step_is_the_commands_or_its_ceiling_and_its_lead_is_bounded() {
        use rand::{RngExt, SeedableRng};
        let arm = Arm::new(Model::Ur3e);
        let p = LoopParams::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(33);
        let q0 = [0.0, -1.3, 1.2, -1.87, -1.57, 0.0];
        let mut c = CommandState::new(CB3);
        c.step_time(&state_at(0.0, q0), CB3, p.robot_stale_s);
        let mut last = q0;
        let mut desired = q0;
        for k in 1..3000 {
            c.step_time(&state_at(k as f64 * CB3, c.q), CB3, p.robot_stale_s);
            // Jumps of up to 0.1 rad and target speeds of up to 4 rad/s, either way.
            if rng.random_bool(0.3) {
                desired = std::array::from_fn(|j| desired[j] + rng.random_range(-0.1..0.1));
            }
            c.target_speed = Some(std::array::from_fn(|_| rng.random_range(-4.0..4.0)));
            let before = c.q;
            c.q = c.limit(&arm, &p, CB3, &desired, p.speed_fraction, None);
            let set = c.setpoint(
                &arm,
                SERVO,
                CB3,
                (1.0, p.speed_fraction),
                rng.random_bool(0.9),
            );
            for j in 0..6 {
                let vmax = arm.spec().max_speed[j] * p.speed_fraction;
                let step = (set[j] - last[j]).abs();
                let own = (c.q[j] - before[j]).abs();
                assert!(
                    step <= own.max(vmax * CB3) + 1e-12,
                    "cycle {k} joint {j}: step {step}, the command's {own}"
                );
                assert!(
                    c.lead[j].abs() <= SERVO.0 * vmax + 1e-12,
                    "lead {}",
                    c.lead[j]
                );
            }
            last = set;
        }
    }

    #[test]
    fn no_lead_after_a_start_nor_in_a_cycle_without_controller_time() {
        let arm = Arm::new(Model::Ur3e);
        let p = LoopParams::default();
        let q0 = [0.0, -1.3, 1.2, -1.87, -1.57, 0.0];
        let mut c = CommandState::new(CB3);
        let mut state = state_at(0.0, q0);
        // The arm moves as fast as two cycles of the budget take to stop, the goal stands: a
        // catch-up, but none to take a change from.
        state.actual_qd = [
            0.0,
            0.0,
            2.0 * p.max_joint_accel_rad_s2 * CB3,
            0.0,
            0.0,
            0.0,
        ];
        c.step_time(&state, CB3, p.robot_stale_s);
        c.target_speed = Some([0.0; 6]);
        c.q = c.limit(&arm, &p, CB3, &q0, 1.0, None);
        assert_eq!(c.setpoint(&arm, SERVO, CB3, (0.3, 1.0), true), c.q);
        // Next cycle it leads …
        c.step_time(&state_at(CB3, c.q), CB3, p.robot_stale_s);
        c.q = c.limit(&arm, &p, CB3, &q0, 1.0, None);
        let set = c.setpoint(&arm, SERVO, CB3, (0.3, 1.0), true);
        assert!((set[2] - c.q[2]).abs() > 1e-4, "{set:?} vs {:?}", c.q);
        // … and the same state again changes nothing.
        c.step_time(&state_at(CB3, c.q), CB3, p.robot_stale_s);
        assert_eq!(c.setpoint(&arm, SERVO, CB3, (0.3, 1.0), true), set);
        // Not following the goal (a hold, a path): the lead goes.
        c.step_time(&state_at(2.0 * CB3, c.q), CB3, p.robot_stale_s);
        let hold = c.stand_still();
        c.q = c.limit(&arm, &p, CB3, &hold, 1.0, None);
        let set = c.setpoint(&arm, SERVO, CB3, (0.3, 1.0), false);
        assert!(c.lead.iter().all(|l| *l == 0.0), "{:?}", c.lead);
        assert_eq!(set, c.q);
    }

    /// The loop commands a goal far away (at its speed ceiling, on every joint) to a controller
    /// that takes, at each period, the newest setpoint arrived, each arriving 0 to `max_late`
    /// periods late (seeded, in order, as over TCP), and that acknowledges what it took in its
    /// next state. Returns the fastest any taken setpoint moved from the one taken before, as a
    /// share of the joint's maximum speed, when the loop bounds its setpoints by what the
    /// controller may hold (`bounded`) or only by its own previous one.
    fn fastest_taken_setpoint(bounded: bool, max_late: u64, seed: u64) -> f64 {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let arm = Arm::new(Model::Ur3e);
        let p = LoopParams {
            max_tcp_speed_m_s: 100.0,
            ..LoopParams::default()
        };
        let q0 = [0.0, -1.3, 1.2, -1.87, -1.57, 0.0];
        let far: [f64; 6] = std::array::from_fn(|j| q0[j] + 3.0);
        let mut c = CommandState::new(PERIOD);
        // (arrives at tick, seq, setpoint), in sending order.
        let mut wire: std::collections::VecDeque<(u64, i32, [f64; 6])> = Default::default();
        let (mut taken, mut taken_at, mut acked) = (q0, 0u64, 0i32);
        let mut fastest: f64 = 0.0;
        let mut last_arrival = 0;
        for tick in 0..3000u64 {
            // The controller's period: the newest arrived, judged against the one it had.
            while wire.front().is_some_and(|w| w.0 <= tick) {
                let Some((_, seq, set)) = wire.pop_front() else {
                    break;
                };
                if wire.front().is_some_and(|w| w.0 <= tick) {
                    continue; // a newer one arrived in the same period
                }
                let dt = (tick - taken_at) as f64 * PERIOD;
                for j in 0..6 {
                    let share = (set[j] - taken[j]).abs() / dt / arm.spec().max_speed[j];
                    fastest = fastest.max(share);
                }
                (taken, taken_at, acked) = (set, tick, seq);
            }
            // The loop answers this period's state.
            let mut state = state_at(tick as f64 * PERIOD, taken);
            state.acked_seq = acked;
            c.step_time(&state, PERIOD, p.robot_stale_s);
            if bounded {
                c.held.acknowledge(acked, state.controller_s);
            }
            c.q = c.limit(&arm, &p, PERIOD, &far, 0.75, None);
            let set = c.setpoint(&arm, SERVO, PERIOD, (0.3, 0.75), false);
            let seq = tick as i32 + 1;
            c.held.note_sent(seq, set);
            last_arrival = (tick + 1 + rng.random_range(0..=max_late)).max(last_arrival);
            wire.push_back((last_arrival, seq, set));
        }
        fastest
    }

    #[test]
    fn setpoints_that_land_late_or_bunched_never_make_a_jump() {
        // On time every period, the ceiling (0.75 of the maximum) is what the controller sees.
        let on_time = fastest_taken_setpoint(true, 0, 1);
        assert!((on_time - 0.75).abs() < 1e-6, "{on_time}");
        for seed in 0..8 {
            for max_late in [1, 2, 3, 5] {
                let f = fastest_taken_setpoint(true, max_late, seed);
                assert!(f <= 1.0 + 1e-9, "seed {seed}, late ≤ {max_late}: {f}");
            }
        }
        // Bounded only by its own previous setpoint, a late one taken alone and the next a
        // period after it is two of the loop's steps in one period: 1.5 × the maximum.
        let unbounded = fastest_taken_setpoint(false, 1, 0);
        assert!(unbounded > 1.4, "{unbounded}");
    }

    #[test]
    fn the_delay_is_measured_from_acknowledgements_and_survives_wrapping() {
        let mut d = DelayEstimator::new(PERIOD);
        let mut seq = i32::MAX - 100;
        for k in 0..400 {
            let t = k as f64 * PERIOD;
            d.note(seq, t);
            // Acknowledged 8 ms later.
            if k >= 4 {
                d.measure(seq.wrapping_sub(4), t);
            }
            seq = seq.wrapping_add(1);
        }
        assert!((d.estimate() - 0.008).abs() < 1e-4, "{}", d.estimate());
    }
}
