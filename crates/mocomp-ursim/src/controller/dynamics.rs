//! Joint dynamics: the servo, speed, move and stop motions, their integration, and the limits
//! whose breach is a protective stop (see the parent module's doc for the model).

use super::*;
use mocomp_kin::Selection;

#[derive(Debug, Clone, Copy)]
pub(super) struct Servo {
    pub(super) target: [f64; 6],
    pub(super) lookahead: f64,
    pub(super) gain: f64,
    pub(super) changed_s: f64,
}

#[derive(Debug, Clone, Copy)]
pub(super) struct MoveProfile {
    pub(super) start: [f64; 6],
    pub(super) delta: [f64; 6],
    pub(super) dist: f64,
    pub(super) v: f64,
    pub(super) a: f64,
    pub(super) t_acc: f64,
    pub(super) t_total: f64,
    pub(super) elapsed: f64,
}

impl MoveProfile {
    pub(super) fn new(start: [f64; 6], goal: [f64; 6], v: f64, a: f64) -> Self {
        let delta: [f64; 6] = std::array::from_fn(|j| goal[j] - start[j]);
        let dist = delta.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        let (v, t_acc, t_total) = if dist <= 0.0 {
            (v, 0.0, 0.0)
        } else if dist < v * v / a {
            let ta = (dist / a).sqrt();
            (a * ta, ta, 2.0 * ta)
        } else {
            (v, v / a, dist / v + v / a)
        };
        Self {
            start,
            delta,
            dist,
            v,
            a,
            t_acc,
            t_total,
            elapsed: 0.0,
        }
    }

    /// Fraction of the way done at `t`.
    pub(super) fn fraction(&self, t: f64) -> f64 {
        if self.dist <= 0.0 || t >= self.t_total {
            return 1.0;
        }
        let s = if t < self.t_acc {
            0.5 * self.a * t * t
        } else if t < self.t_total - self.t_acc {
            0.5 * self.a * self.t_acc * self.t_acc + self.v * (t - self.t_acc)
        } else {
            let r = self.t_total - t;
            self.dist - 0.5 * self.a * r * r
        };
        (s / self.dist).clamp(0.0, 1.0)
    }
}

#[derive(Debug, Clone, Copy)]
pub(super) enum Motion {
    Idle,
    Servo(Servo),
    Speed {
        qd: [f64; 6],
        accel: f64,
    },
    Move(MoveProfile),
    Linear(LinearMove),
    /// `freedrive_mode()`: the arm yields to the wrench on its tool (a hand pushing it).
    Freedrive,
    Stop {
        decel: f64,
    },
}

/// Free-drive's compliance: a force of 1 N moves the tool this fast (m/s), a torque of 1 N·m
/// turns it this fast (rad/s). UR does not publish its free-drive law; these make a 20 N push
/// move the coil at 0.1 m/s, about a hand's pace.
const FREEDRIVE_M_S_PER_N: f64 = 0.005;
const FREEDRIVE_RAD_S_PER_NM: f64 = 0.05;

/// `movel`: the tool on a straight line (its rotation slerped) with a trapezoidal profile of the
/// tool's speed, the joints from IK each cycle on the branch the arm is on.
#[derive(Debug, Clone, Copy)]
pub(super) struct LinearMove {
    pub(super) start: Isometry3<f64>,
    pub(super) goal: Isometry3<f64>,
    /// The profile along the path: translation in m (or, for a pure rotation, the angle in rad).
    pub(super) profile: MoveProfile,
}

pub(super) fn approach(v: f64, target: f64, step: f64) -> f64 {
    if (target - v).abs() <= step {
        target
    } else {
        v + step * (target - v).signum()
    }
}

impl Controller {
    pub(super) fn start_servo(
        &mut self,
        target: [f64; 6],
        t: f64,
        lookahead: f64,
        gain: f64,
    ) -> bool {
        if !(0.001..=1.0).contains(&t)
            || !(0.03..=0.2).contains(&lookahead)
            || !(100.0..=2000.0).contains(&gain)
        {
            self.stop_program(format!(
                "servoj: t = {t}, lookahead_time = {lookahead}, gain = {gain} outside \
                 [0.001, 1], [0.03, 0.2], [100, 2000]"
            ));
            return false;
        }
        let (prev, since) = match self.motion {
            Motion::Servo(s) => (s.target, s.changed_s),
            _ => (self.q, self.time_s - t),
        };
        if target != prev {
            let dt = (self.time_s - since).max(t).max(self.period);
            for j in 0..6 {
                let limit = self.spec.max_speed[j] * self.config.setpoint_speed_factor;
                let v = (target[j] - prev[j]).abs() / dt;
                if v / limit > self.setpoint_peak.0 {
                    self.setpoint_peak = (v / limit, self.time_s);
                }
                if !v.is_finite() || v > limit {
                    self.protective_stop(format!(
                        "C204A3 invalid setpoint: joint {} servo target moves {:.4} rad in \
                         {:.1} ms ({:.2} rad/s, limit {:.2})",
                        j + 1,
                        (target[j] - prev[j]).abs(),
                        dt * 1e3,
                        v,
                        limit
                    ));
                    return false;
                }
            }
            if !self.arm.limits().contains(&target, 0.0) {
                self.protective_stop("servo target outside the joint limits".into());
                return false;
            }
        }
        let changed_s = if target != prev || !matches!(self.motion, Motion::Servo(_)) {
            self.time_s
        } else {
            since
        };
        self.motion = Motion::Servo(Servo {
            target,
            lookahead,
            gain,
            changed_s,
        });
        true
    }

    pub(super) fn start_speed(&mut self, qd: [f64; 6], accel: f64) -> bool {
        for (j, v) in qd.iter().enumerate() {
            if !v.is_finite() || v.abs() > self.spec.max_speed[j] {
                self.protective_stop(format!(
                    "joint {} speed command {v:.3} rad/s above its limit {:.3}",
                    j + 1,
                    self.spec.max_speed[j]
                ));
                return false;
            }
        }
        let accel = if accel.is_finite() && accel > 0.0 {
            accel
        } else {
            1.4
        };
        self.motion = Motion::Speed { qd, accel };
        true
    }

    pub(super) fn start_move(&mut self, goal: [f64; 6], v: f64, a: f64) -> bool {
        if !goal.iter().all(|x| x.is_finite()) || !self.arm.limits().contains(&goal, 0.0) {
            self.stop_program("movej: target outside the joint limits".into());
            return false;
        }
        let v = if v.is_finite() && v > 0.0 {
            v.min(
                self.spec
                    .max_speed
                    .iter()
                    .fold(f64::INFINITY, |m, x| m.min(*x)),
            )
        } else {
            1.05
        };
        let a = if a.is_finite() && a > 0.0 {
            a.min(40.0)
        } else {
            1.4
        };
        self.motion = Motion::Move(MoveProfile::new(self.q, goal, v, a));
        true
    }

    /// `movel` to `goal` (`base_from_tcp`) at tool speed `v` (m/s) and acceleration `a` (m/s²);
    /// a pure rotation takes them as rad/s and rad/s², as URScript does. Refused (the program
    /// stops) when the goal is not finite or has no IK solution within the joint limits.
    pub(super) fn start_linear(&mut self, goal: Isometry3<f64>, v: f64, a: f64) -> bool {
        let finite = goal.translation.vector.iter().all(|x| x.is_finite())
            && goal.rotation.coords.iter().all(|x| x.is_finite());
        if !finite
            || self
                .arm
                .ik_closest(&goal, &self.q, &Selection::default())
                .is_err()
        {
            self.stop_program("movel: the target pose is not reachable".into());
            return false;
        }
        let start = self.arm.fk(&self.q);
        let trans = (goal.translation.vector - start.translation.vector).norm();
        let dist = if trans > 1e-6 {
            trans
        } else {
            start.rotation.angle_to(&goal.rotation)
        };
        let v = if v.is_finite() && v > 0.0 {
            v.min(3.0)
        } else {
            0.25
        };
        let a = if a.is_finite() && a > 0.0 {
            a.min(15.0)
        } else {
            1.2
        };
        let mut end = [0.0; 6];
        end[0] = dist;
        self.motion = Motion::Linear(LinearMove {
            start,
            goal,
            profile: MoveProfile::new([0.0; 6], end, v, a),
        });
        true
    }

    pub(super) fn integrate(&mut self) {
        let dt = self.period;
        let ds = dt * self.scaling();
        let q0 = self.q;
        let qd0 = self.qd;
        match &mut self.motion {
            Motion::Idle => {
                for j in 0..6 {
                    self.qd_int[j] = approach(self.qd_int[j], 0.0, self.config.stop_decel * dt);
                    self.q[j] += self.qd_int[j] * dt;
                }
            }
            Motion::Servo(s) => {
                for j in 0..6 {
                    let vmax = self.spec.max_speed[j];
                    let amax = self.config.max_accel[j];
                    let acc = (s.gain * (s.target[j] - self.q[j] - s.lookahead * self.qd_int[j]))
                        .clamp(-amax, amax);
                    self.qd_int[j] = (self.qd_int[j] + acc * ds).clamp(-vmax, vmax);
                    self.q[j] += self.qd_int[j] * ds;
                }
            }
            Motion::Speed { qd, accel } => {
                for ((v, target), q) in self.qd_int.iter_mut().zip(qd.iter()).zip(&mut self.q) {
                    *v = approach(*v, *target, *accel * ds);
                    *q += *v * ds;
                }
            }
            Motion::Move(m) => {
                m.elapsed += ds;
                let f = m.fraction(m.elapsed);
                for j in 0..6 {
                    let next = m.start[j] + m.delta[j] * f;
                    self.qd_int[j] = (next - self.q[j]) / ds.max(1e-12);
                    self.q[j] = next;
                }
                if m.elapsed >= m.t_total {
                    self.qd_int = [0.0; 6];
                    self.motion = Motion::Idle;
                }
            }
            Motion::Linear(m) => {
                m.profile.elapsed += ds;
                let f = m.profile.fraction(m.profile.elapsed);
                let t = m
                    .start
                    .translation
                    .vector
                    .lerp(&m.goal.translation.vector, f);
                let r = m.start.rotation.slerp(&m.goal.rotation, f);
                let pose = Isometry3::from_parts(t.into(), r);
                let done = m.profile.elapsed >= m.profile.t_total;
                self.follow_line(&pose, done, ds);
            }
            Motion::Freedrive => self.yield_to_hand(dt),
            Motion::Stop { decel } => {
                let mut moving = false;
                for j in 0..6 {
                    self.qd_int[j] = approach(self.qd_int[j], 0.0, *decel * dt);
                    self.q[j] += self.qd_int[j] * dt;
                    moving |= self.qd_int[j] != 0.0;
                }
                if !moving {
                    self.motion = Motion::Idle;
                }
            }
        }
        for j in 0..6 {
            self.qd[j] = (self.q[j] - q0[j]) / dt;
            self.qdd[j] = (self.qd[j] - qd0[j]) / dt;
        }
    }

    /// movel's next pose: the joints that reach it nearest the current ones, or a protective
    /// stop where none is near enough (a singularity) or none reaches it.
    fn follow_line(&mut self, pose: &Isometry3<f64>, done: bool, ds: f64) {
        match self
            .arm
            .ik_closest(pose, &self.q, &Selection::tracking(0.0))
        {
            Ok(c) => {
                let fast = (0..6).any(|j| {
                    (c.joints[j] - self.q[j]).abs() / ds.max(1e-12)
                        > self.spec.max_speed[j] * self.config.setpoint_speed_factor
                });
                if fast {
                    // Near a singularity a straight line asks for joint speeds no arm has.
                    self.qd_int = [0.0; 6];
                    self.motion = Motion::Idle;
                    self.protective_stop(
                        "movel: a joint would exceed its speed limit (near a singularity)".into(),
                    );
                } else {
                    for j in 0..6 {
                        self.qd_int[j] = (c.joints[j] - self.q[j]) / ds.max(1e-12);
                    }
                    self.q = c.joints;
                    if done {
                        self.qd_int = [0.0; 6];
                        self.motion = Motion::Idle;
                    }
                }
            }
            Err(_) => {
                self.qd_int = [0.0; 6];
                self.motion = Motion::Idle;
                self.protective_stop("movel: the path leaves the arm's reach".into());
            }
        }
    }

    /// Free-drive: the joints move at the speeds that give the tool the twist the hand's wrench
    /// asks for, within each joint's speed and acceleration.
    fn yield_to_hand(&mut self, dt: f64) {
        let w = self.tcp_force;
        let twist = Vector6::new(
            w[0] * FREEDRIVE_M_S_PER_N,
            w[1] * FREEDRIVE_M_S_PER_N,
            w[2] * FREEDRIVE_M_S_PER_N,
            w[3] * FREEDRIVE_RAD_S_PER_NM,
            w[4] * FREEDRIVE_RAD_S_PER_NM,
            w[5] * FREEDRIVE_RAD_S_PER_NM,
        );
        // Joint speeds for that tool twist (least squares near a singularity), within
        // each joint's speed and acceleration.
        let qd = self
            .arm
            .jacobian(&self.q)
            .svd(true, true)
            .solve(&twist, 1e-6)
            .unwrap_or_else(|_| Vector6::zeros());
        for j in 0..6 {
            let vmax = self.spec.max_speed[j];
            let target = qd[j].clamp(-vmax, vmax);
            self.qd_int[j] = approach(self.qd_int[j], target, self.config.max_accel[j] * dt);
            self.q[j] += self.qd_int[j] * dt;
        }
    }

    pub(super) fn check_limits(&mut self) {
        let lim = *self.arm.limits();
        for j in 0..6 {
            if self.q[j] < lim.lower[j] || self.q[j] > lim.upper[j] {
                self.q[j] = self.q[j].clamp(lim.lower[j], lim.upper[j]);
                self.qd_int = [0.0; 6];
                self.protective_stop(format!("joint {} reached its position limit", j + 1));
                self.motion = Motion::Idle;
            }
        }
    }
}
