//! The head robot following a head-motion trace within its own limits, and what it could not
//! follow.
//!
//! A recorded head can move faster than the robot that plays it: a subject's head swings its
//! weight in a few milliseconds, the arm's elbow turns at most 180 °/s. Sent as they are, such
//! setpoints trip the controller's protective stop (URControl's C204A3) and the run ends. Here
//! every setpoint moves each joint at most its maximum speed and changes that speed at most the
//! acceleration budget per period; where that holds the head back, the robot lags the trace and
//! catches up as fast as it may, without overshoot. The intervals it lagged, and by how much, are
//! the report: the run then scores the head the robot really played, and says so.
//!
//! [`HeadPlayer`] puts it together: the trace's pose at each tick, the head robot's joints for it
//! on the branch it is on, and the drive's setpoint.
//!
//! Pure arithmetic on joint vectors: no I/O, no clock.

use mocomp_geom::nalgebra::Isometry3;
use mocomp_kin::{Arm, Selection};
use mocomp_sim::motion::Trajectory;

/// The head robot's limits as the drive applies them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadLimits {
    /// Largest joint speed per joint, rad/s.
    pub speed_rad_s: [f64; 6],
    /// Largest change of joint speed, rad/s², on every joint.
    pub accel_rad_s2: f64,
}

/// An interval the head robot could not follow the trace.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Lag {
    /// From, s on the run's clock.
    pub from_s: f64,
    /// To, s (the tick it was back on the trace, or the run's end).
    pub to_s: f64,
    /// The largest joint error in it, rad.
    pub max_joint_rad: f64,
}

/// The head robot's setpoints along a trace, each within [`HeadLimits`] of the last.
#[derive(Debug, Clone)]
pub struct HeadDrive {
    limits: HeadLimits,
    period_s: f64,
    q: [f64; 6],
    qd: [f64; 6],
    /// The trace's previous joint target (for its speed, fed forward).
    target_prev: Option<[f64; 6]>,
    lags: Vec<Lag>,
}

/// A joint further than this from the trace counts as not following it, rad (0.1 mrad: a
/// tenth of a millimetre at the phantom).
const ON_TRACE_RAD: f64 = 1e-4;

/// The ceiling of joint acceleration the drive allows, rad/s²: the largest a `movej` may ask
/// of the controller (URScript's, and the simulated controller's, upper bound).
pub const HEAD_ACCEL_RAD_S2: f64 = 40.0;

impl HeadLimits {
    /// `model`'s: its joints' maximum speeds (the controller stops on a setpoint beyond 1.2×
    /// them) and [`HEAD_ACCEL_RAD_S2`].
    pub fn of(model: mocomp_kin::Model) -> Self {
        Self {
            speed_rad_s: model.spec().max_speed,
            accel_rad_s2: HEAD_ACCEL_RAD_S2,
        }
    }
}

impl HeadDrive {
    /// A drive from the robot at rest at `q`, ticking every `period_s`.
    pub fn new(q: [f64; 6], period_s: f64, limits: HeadLimits) -> Self {
        Self {
            limits,
            period_s,
            q,
            qd: [0.0; 6],
            target_prev: None,
            lags: Vec::new(),
        }
    }

    /// The next setpoint towards the trace's joint `target` at run time `t_s`: the target
    /// itself when it is within the limits, else as close as they allow.
    pub fn next(&mut self, t_s: f64, target: &[f64; 6]) -> [f64; 6] {
        let dt = self.period_s;
        let prev = self.target_prev.unwrap_or(*target);
        self.target_prev = Some(*target);
        let dv = self.limits.accel_rad_s2 * dt;
        // Braking planned a little below the budget, so the discrete stop never needs more.
        let brake = 0.8 * self.limits.accel_rad_s2;
        let mut worst = 0.0f64;
        for j in 0..6 {
            let vmax = self.limits.speed_rad_s[j];
            // The gap to the trace as it was, closed on top of the trace's own motion: all of
            // it in one period when the limits allow, else no faster than a stop at the
            // acceleration budget still lands on it (no overshoot).
            let gap = prev[j] - self.q[j];
            let v_trace = (target[j] - prev[j]) / dt;
            // (The stop's speed in discrete steps: n periods from rest cover brake·dt²·n(n+1)/2.)
            let half = 0.5 * brake * dt;
            let stoppable = (half * half + 2.0 * brake * gap.abs()).sqrt() - half;
            let close = gap.signum() * (gap.abs() / dt).min(stoppable);
            let v = (v_trace + close)
                .clamp(self.qd[j] - dv, self.qd[j] + dv)
                .clamp(-vmax, vmax);
            self.qd[j] = v;
            self.q[j] += v * dt;
            worst = worst.max((target[j] - self.q[j]).abs());
        }
        self.note(t_s, worst);
        self.q
    }

    fn note(&mut self, t_s: f64, error: f64) {
        let lagging = error > ON_TRACE_RAD;
        match self.lags.last_mut() {
            Some(l) if l.to_s.is_nan() => {
                l.max_joint_rad = l.max_joint_rad.max(error);
                if !lagging {
                    l.to_s = t_s;
                }
            }
            _ if lagging => self.lags.push(Lag {
                from_s: t_s,
                to_s: f64::NAN,
                max_joint_rad: error,
            }),
            _ => {}
        }
    }

    /// The intervals the robot lagged the trace, the last closed at `end_s` if still open.
    pub fn lags(&self, end_s: f64) -> Vec<Lag> {
        self.lags
            .iter()
            .map(|l| Lag {
                to_s: if l.to_s.is_nan() { end_s } else { l.to_s },
                ..*l
            })
            .collect()
    }
}

/// The head robot playing a head's trajectory: each tick, the joints that put the head where the
/// trajectory has it one period later (where the setpoint takes effect), within the robot's
/// limits. The experiment's runs and the oracle's look-ahead play it alike, so they see one head.
#[derive(Debug, Clone)]
pub struct HeadPlayer {
    trajectory: Trajectory,
    /// The head at rest in the world (the head robot's base).
    world_from_rest: Isometry3<f64>,
    head_from_e2: Isometry3<f64>,
    arm: Arm,
    period_s: f64,
    /// The joints on the trace at the last tick (where the next IK starts from).
    q_trace: [f64; 6],
    drive: HeadDrive,
}

impl HeadPlayer {
    /// A player of `trajectory` for the head robot `arm` at rest at `q_start`, the head at
    /// `world_from_rest` at rest and `e2_from_head` on the flange.
    pub fn new(
        trajectory: Trajectory,
        world_from_rest: Isometry3<f64>,
        e2_from_head: &Isometry3<f64>,
        arm: Arm,
        q_start: [f64; 6],
        period_s: f64,
    ) -> Self {
        Self {
            trajectory,
            world_from_rest,
            head_from_e2: e2_from_head.inverse(),
            drive: HeadDrive::new(q_start, period_s, HeadLimits::of(arm.model())),
            arm,
            period_s,
            q_trace: q_start,
        }
    }

    /// The setpoint to send at run time `t_s`.
    pub fn setpoint(&mut self, t_s: f64) -> [f64; 6] {
        let target = self.world_from_rest
            * self.trajectory.rest_from_head(t_s + self.period_s)
            * self.head_from_e2;
        // Where no solution is near (a pose out of reach), the head robot stays on the last one.
        if let Ok(c) = self
            .arm
            .ik_closest(&target, &self.q_trace, &Selection::tracking(0.02))
        {
            self.q_trace = c.joints;
        }
        self.drive.next(t_s, &self.q_trace)
    }

    /// The trajectory played.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    /// Where it lagged the trace, the last interval closed at `end_s` if still open.
    pub fn lags(&self, end_s: f64) -> Vec<Lag> {
        self.drive.lags(end_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD: f64 = 0.002;

    fn limits() -> HeadLimits {
        HeadLimits {
            speed_rad_s: [3.0; 6],
            accel_rad_s2: 40.0,
        }
    }

    /// A smooth joint path within the limits from rest: 0.5 rad/s peak, 3 rad/s² peak.
    fn gentle(t: f64) -> [f64; 6] {
        std::array::from_fn(|j| 0.1 * (j as f64) + 0.5 / 6.0 * (1.0 - (6.0 * t).cos()))
    }

    #[test]
    fn a_trace_within_the_limits_is_followed_exactly() {
        let mut d = HeadDrive::new(gentle(0.0), PERIOD, limits());
        for k in 0..5000 {
            let t = k as f64 * PERIOD;
            let q = d.next(t, &gentle(t));
            for (j, (a, b)) in q.iter().zip(gentle(t)).enumerate() {
                assert!((a - b).abs() < 1e-9, "t {t} joint {j}");
            }
        }
        assert!(d.lags(10.0).is_empty());
    }

    #[test]
    fn a_jump_is_reached_within_the_limits_without_overshoot_and_reported() {
        let start = [0.0; 6];
        let goal = [0.0, 0.0, 0.6, 0.0, 0.0, 0.0];
        let mut d = HeadDrive::new(start, PERIOD, limits());
        let (mut q_prev, mut v_prev) = (start, [0.0; 6]);
        let mut arrived = None;
        for k in 0..2000 {
            let t = k as f64 * PERIOD;
            let q = d.next(t, &goal);
            for j in 0..6 {
                let v = (q[j] - q_prev[j]) / PERIOD;
                assert!(v.abs() <= 3.0 + 1e-9, "speed {v} at {t}");
                assert!(
                    (v - v_prev[j]).abs() / PERIOD <= 40.0 + 1e-6,
                    "accel at {t}"
                );
                assert!(q[j] <= goal[j] + 1e-12, "overshoot {} at {t}", q[j]);
                v_prev[j] = v;
            }
            q_prev = q;
            if arrived.is_none() && (q[2] - 0.6).abs() <= ON_TRACE_RAD {
                arrived = Some(t);
            }
        }
        // A rest-to-rest move of 0.6 rad at 40 rad/s² takes 2·√(0.6/40) = 0.245 s at least.
        let t = arrived.expect("arrived");
        assert!((0.24..0.35).contains(&t), "arrived after {t} s");
        let lags = d.lags(4.0);
        assert_eq!(lags.len(), 1, "{lags:?}");
        assert_eq!(lags[0].from_s, 0.0);
        assert!((lags[0].to_s - t).abs() <= PERIOD, "{lags:?} against {t}");
        assert!((lags[0].max_joint_rad - 0.6).abs() < 0.01);
    }

    #[test]
    fn a_trace_too_fast_is_followed_at_the_speed_limit_and_caught_up_with() {
        // 5 rad/s on joint 1 for 0.2 s, then still: the drive runs at 3 rad/s, behind, and
        // lands on the trace's end.
        let trace = |t: f64| -> [f64; 6] {
            let mut q = [0.0; 6];
            q[1] = 5.0 * t.clamp(0.0, 0.2);
            q
        };
        let mut d = HeadDrive::new(trace(0.0), PERIOD, limits());
        let mut last = [0.0; 6];
        for k in 0..1000 {
            let t = k as f64 * PERIOD;
            last = d.next(t, &trace(t));
            assert!(last[1] <= 1.0 + 1e-12, "overshoot {} at {t}", last[1]);
        }
        assert!(
            (last[1] - 1.0).abs() < 1e-9,
            "ends on the trace: {}",
            last[1]
        );
        let lags = d.lags(2.0);
        assert_eq!(lags.len(), 1, "{lags:?}");
        // Behind from about when its speed passed the limit; 1 rad at 3 rad/s is 0.33 s plus
        // the speeding up and slowing down.
        assert!(lags[0].from_s < 0.05, "{lags:?}");
        assert!((0.33..0.5).contains(&lags[0].to_s), "{lags:?}");
        assert!(lags[0].max_joint_rad > 0.3, "{lags:?}");
    }
}
