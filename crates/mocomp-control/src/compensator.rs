//! One compensation cycle, at the robot's rate, on an injectable clock: newest tracker sample and
//! robot state → supervisor → predicted head pose → goal `base_from_flange = base_from_tracker ·
//! tracker_from_head · head_from_coil_goal · coil_from_flange` → IK on the current branch →
//! limits → collision check of the command → `servo`. No allocation, no lock, no logging: the
//! caller gets a [`CycleRecord`] (`Copy`) to queue for a logger.

use crate::config::LoopConfig;
use crate::predict::PosePredictor;
use mocomp_geom::nalgebra::{Isometry3, Point3, Vector3};
use mocomp_geom::{PoseSample, PoseSource};
use mocomp_kin::{Arm, Selection};
use mocomp_ur::{Robot, RobotFault};

/// Why the loop holds (or stopped) the robot. Each is a named, tested rule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Reason {
    /// No tracker sample yet.
    NoTracker,
    /// The newest sample is older than `tracker_stale_s` (s).
    TrackerStale(f64),
    /// `frozen_samples` identical samples in a row.
    TrackerFrozen,
    /// The tracker marks the marker invalid (lost, out of view, error too large).
    MarkerInvalid,
    /// The head moves faster than the robot may follow (m/s, rad/s).
    HeadTooFast(f64, f64),
    /// The robot reports a fault.
    Robot(RobotFault),
    /// The robot's state is older than `robot_stale_periods`.
    RobotStale,
    /// The goal is at or near a singularity (its margin).
    Singular(f64),
    /// No IK solution on the current branch within the joint limits.
    Unreachable,
    /// The goal puts the coil closer to the head than `coil_min_distance_m` (its distance, m).
    GoalInsideHead(f64),
    /// The command would bring a link (index) closer than the clearance (distance, m).
    LinkCollision(usize, f64),
    /// The command would bring the coil closer than `coil_min_distance_m` (m).
    CoilCollision(f64),
    /// The coil near the head but off its approach axis (lateral offset, m).
    OffApproachAxis(f64),
}

/// What the loop is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// Following the goal with the servo.
    Tracking,
    /// Moving slowly towards a goal far from the coil (after a hold).
    Approaching,
    /// Holding the last safe command (decelerating to standstill) for a reason; resumes by
    /// itself when the reason has been clear for `resume_after_s`.
    Holding(Reason),
    /// The robot is stopped by a fault; commands resume when the robot reports healthy again.
    Faulted(Reason),
}

/// Something worth logging, at most one per cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Event {
    /// The loop started holding (or stopped) for a reason.
    Hold(Reason),
    /// The loop resumed tracking.
    Resume,
    /// A tracker sample was rejected as an outlier (implied m/s, rad/s).
    Outlier(f64, f64),
    /// The loop switched from approaching to tracking.
    Reached,
}

/// One cycle, for the log.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CycleRecord {
    /// Loop time, s.
    pub t: f64,
    /// The mode after this cycle.
    pub mode: Mode,
    /// The event of this cycle.
    pub event: Option<Event>,
    /// Age of the newest accepted tracker sample, s.
    pub sample_age_s: f64,
    /// Prediction horizon from the newest sample, s (0 without prediction).
    pub horizon_s: f64,
    /// Estimated command delay (send → acknowledged in the robot's state), s.
    pub command_delay_s: f64,
    /// Joints commanded.
    pub q_command: [f64; 6],
    /// Joints measured.
    pub q_actual: [f64; 6],
    /// The goal flange pose computed this cycle, if any.
    pub goal: Option<Isometry3<f64>>,
    /// Estimated head speed, m/s and rad/s.
    pub head_speed: (f64, f64),
    /// Compute time of the cycle, ns (filled by the caller that owns a clock for it).
    pub compute_ns: u64,
}

const ACK_RING: usize = 64;

/// The compensation loop's state.
#[derive(Debug, Clone)]
pub struct Compensator {
    cfg: LoopConfig,
    arm: Arm,
    coil_from_flange: Isometry3<f64>,
    period: f64,
    predictor: PosePredictor,
    last_raw: Option<PoseSample>,
    last_valid: bool,
    identical: u32,
    q_cmd: [f64; 6],
    v_cmd: [f64; 6],
    have_cmd: bool,
    mode: Mode,
    clear_since: Option<f64>,
    stop_sent: bool,
    command_delay: f64,
    acks: [(i32, f64); ACK_RING],
    ack_head: usize,
    ack_len: usize,
}

impl Compensator {
    /// A loop for `arm` (its model fixes the speeds and limits) at the robot's `period_s`.
    pub fn new(cfg: LoopConfig, arm: Arm, period_s: f64) -> Self {
        let coil_from_flange = cfg.flange_from_coil.inverse();
        let predictor = PosePredictor::new(cfg.predictor);
        Self {
            command_delay: period_s,
            cfg,
            arm,
            coil_from_flange,
            period: period_s,
            predictor,
            last_raw: None,
            last_valid: true,
            identical: 0,
            q_cmd: [0.0; 6],
            v_cmd: [0.0; 6],
            have_cmd: false,
            mode: Mode::Holding(Reason::NoTracker),
            clear_since: None,
            stop_sent: false,
            acks: [(0, 0.0); ACK_RING],
            ack_head: 0,
            ack_len: 0,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &LoopConfig {
        &self.cfg
    }

    /// The current mode.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The goal flange pose for a head pose (`tracker_from_head`).
    pub fn goal_for(&self, tracker_from_head: &Isometry3<f64>) -> Isometry3<f64> {
        self.cfg.base_from_tracker
            * tracker_from_head
            * self.cfg.head_from_coil_goal
            * self.coil_from_flange
    }

    /// Takes the newest tracker sample, applying the tracker rules. Returns an outlier event.
    fn take_sample(&mut self, s: PoseSample) -> Option<Event> {
        self.last_valid = s.valid;
        if !s.valid {
            return None;
        }
        if let Some(prev) = self.last_raw {
            if prev.tracker_from_marker == s.tracker_from_marker {
                self.identical = self.identical.saturating_add(1);
            } else {
                self.identical = 0;
            }
        }
        if let Some(pred) = self.predictor.predict(s.acquired_s) {
            let dt = (s.acquired_s - self.predictor.time_s()).max(self.period);
            let lin = (pred.translation.vector - s.tracker_from_marker.translation.vector).norm();
            let ang = (pred.rotation.inverse() * s.tracker_from_marker.rotation).angle();
            let (vl, va) = (lin / dt, ang / dt);
            if vl > self.cfg.outlier_speed_m_s || va > self.cfg.outlier_speed_rad_s {
                return Some(Event::Outlier(vl, va));
            }
        }
        self.last_raw = Some(s);
        self.predictor.update(s.acquired_s, &s.tracker_from_marker);
        None
    }

    fn tracker_reason(&mut self, now: f64) -> Option<Reason> {
        if !self.predictor.is_initialised() {
            return Some(Reason::NoTracker);
        }
        if !self.last_valid {
            return Some(Reason::MarkerInvalid);
        }
        let age = now - self.predictor.time_s();
        if age > self.cfg.tracker_stale_s {
            if age > 10.0 * self.cfg.tracker_stale_s {
                // A long dropout: the velocity estimate means nothing any more.
                self.predictor.reset();
                self.last_raw = None;
            }
            return Some(Reason::TrackerStale(age));
        }
        if self.identical >= self.cfg.frozen_samples {
            return Some(Reason::TrackerFrozen);
        }
        let (v, w) = self.predictor.velocity();
        if v.norm() > self.cfg.max_head_speed_m_s || w.norm() > self.cfg.max_head_speed_rad_s {
            return Some(Reason::HeadTooFast(v.norm(), w.norm()));
        }
        None
    }

    fn note_command(&mut self, seq: i32, t: f64) {
        let i = (self.ack_head + self.ack_len) % ACK_RING;
        self.acks[i] = (seq, t);
        if self.ack_len < ACK_RING {
            self.ack_len += 1;
        } else {
            self.ack_head = (self.ack_head + 1) % ACK_RING;
        }
    }

    fn measure_delay(&mut self, acked: i32, received_s: f64) {
        while self.ack_len > 0 {
            let (seq, sent) = self.acks[self.ack_head];
            if acked.wrapping_sub(seq) < 0 {
                break;
            }
            if acked == seq {
                let d = (received_s - sent).max(0.0);
                self.command_delay += 0.05 * (d - self.command_delay);
            }
            self.ack_head = (self.ack_head + 1) % ACK_RING;
            self.ack_len -= 1;
        }
    }

    /// Rate- and acceleration-limits the command towards `desired`, joint by joint, so that each
    /// joint can still stop at `desired` within its acceleration.
    fn limit(&mut self, desired: &[f64; 6], speed_fraction: f64) -> [f64; 6] {
        let dt = self.period;
        let a = self.cfg.max_joint_accel;
        let mut q = self.q_cmd;
        let mut v = self.v_cmd;
        for j in 0..6 {
            let vmax = self.arm.spec().max_speed[j] * speed_fraction;
            let delta = desired[j] - self.q_cmd[j];
            // Largest speed from which the joint can still stop at the target in whole cycles
            // of deceleration a·dt each: n·a·dt with a·dt²·n(n+1)/2 ≤ |delta| (the continuous
            // √(2a|delta|) overshoots by up to a cycle and chatters around a still target).
            let adt2 = a * dt * dt;
            let n = 0.5 * ((1.0 + 8.0 * delta.abs() / adt2).sqrt() - 1.0);
            let v_stop = n * a * dt;
            let want = (delta / dt).clamp(-v_stop, v_stop).clamp(-vmax, vmax);
            v[j] = want.clamp(self.v_cmd[j] - a * dt, self.v_cmd[j] + a * dt);
            q[j] = self.q_cmd[j] + v[j] * dt;
        }
        // The coil's speed limit, on the whole step.
        let p0 = self.arm.fk(&self.q_cmd).translation.vector;
        let p1 = self.arm.fk(&q).translation.vector;
        let speed = (p1 - p0).norm() / dt;
        if speed > self.cfg.max_tcp_speed {
            let k = self.cfg.max_tcp_speed / speed;
            for j in 0..6 {
                v[j] *= k;
                q[j] = self.q_cmd[j] + v[j] * dt;
            }
        }
        self.v_cmd = v;
        q
    }

    /// Checks the motion from `q_prev` to `q` against the head at `base_from_head`: links keep
    /// their clearance, the coil never enters the head, and near the head the coil may move
    /// closer only along its approach axis (moving away or sideways is always allowed, so a
    /// hold never locks itself in).
    pub fn collision(
        &self,
        q_prev: &[f64; 6],
        q: &[f64; 6],
        base_from_head: &Isometry3<f64>,
    ) -> Option<Reason> {
        let head_from_base = base_from_head.inverse();
        let frames = self.arm.link_frames(q);
        let prev_frames = self.arm.link_frames(q_prev);
        // Links up to wrist 2; wrist 3 and the flange are inside the coil's model.
        for i in 1..6 {
            let a = frames[i - 1].translation.vector;
            let b = frames[i].translation.vector;
            for k in 0..=4 {
                let p = a + (b - a) * (f64::from(k) / 4.0);
                let d = self.cfg.head.distance(&(head_from_base * Point3::from(p)))
                    - self.cfg.link_radius_m;
                if d < self.cfg.link_clearance_m {
                    let a0 = prev_frames[i - 1].translation.vector;
                    let b0 = prev_frames[i].translation.vector;
                    let p0 = a0 + (b0 - a0) * (f64::from(k) / 4.0);
                    let d0 = self.cfg.head.distance(&(head_from_base * Point3::from(p0)))
                        - self.cfg.link_radius_m;
                    if d < d0 {
                        return Some(Reason::LinkCollision(i, d));
                    }
                }
            }
        }
        let base_from_coil = frames[6] * self.cfg.flange_from_coil;
        let head_from_coil = head_from_base * base_from_coil;
        let head_from_coil_prev = head_from_base * prev_frames[6] * self.cfg.flange_from_coil;
        let nearest = self.coil_distance(&head_from_coil);
        // Too close, and closer than before: refused. Moving away is always allowed (the head
        // may come to the coil faster than the coil can leave).
        if nearest < self.cfg.coil_min_distance_m - self.cfg.coil_contact_tolerance_m
            && nearest < self.coil_distance(&head_from_coil_prev)
        {
            return Some(Reason::CoilCollision(nearest));
        }
        let centre = head_from_coil.translation.vector;
        let d = self.cfg.head.distance(&Point3::from(centre));
        let prev = head_from_coil_prev.translation.vector;
        let approaching = d < self.cfg.head.distance(&Point3::from(prev)) - 1e-6;
        if d < self.cfg.approach_zone_m && approaching {
            let g = &self.cfg.head_from_coil_goal;
            let axis = g.rotation * Vector3::z();
            let lateral_of = |c: Vector3<f64>| {
                let rel = c - g.translation.vector;
                (rel - axis * rel.dot(&axis)).norm()
            };
            let (lateral, lateral_prev) = (lateral_of(centre), lateral_of(prev));
            // Closer to the head only on the approach axis, or while converging onto it.
            if lateral > self.cfg.approach_tolerance_m && lateral >= lateral_prev {
                return Some(Reason::OffApproachAxis(lateral));
            }
        }
        None
    }

    /// The coil's nearest distance to the head (its face rim, centre and back), m.
    fn coil_distance(&self, head_from_coil: &Isometry3<f64>) -> f64 {
        let r = self.cfg.coil.radius;
        let mut nearest = f64::INFINITY;
        for z in [0.0, -self.cfg.coil.thickness] {
            for k in 0..9 {
                let p = if k == 8 {
                    Point3::new(0.0, 0.0, z)
                } else {
                    let ang = std::f64::consts::TAU * f64::from(k) / 8.0;
                    Point3::new(r * ang.cos(), r * ang.sin(), z)
                };
                nearest = nearest.min(self.cfg.head.distance(&(head_from_coil * p)));
            }
        }
        nearest
    }

    fn enter(&mut self, mode: Mode) -> Option<Event> {
        if self.mode == mode {
            return None;
        }
        let event = match mode {
            Mode::Holding(r) | Mode::Faulted(r) => {
                // Report a new reason only when the kind changes (values move every cycle).
                let same_kind = matches!((self.mode, mode),
                    (Mode::Holding(a), Mode::Holding(b)) | (Mode::Faulted(a), Mode::Faulted(b))
                        if std::mem::discriminant(&a) == std::mem::discriminant(&b));
                (!same_kind).then_some(Event::Hold(r))
            }
            Mode::Tracking => Some(if self.mode == Mode::Approaching {
                Event::Reached
            } else {
                Event::Resume
            }),
            Mode::Approaching => Some(Event::Resume),
        };
        self.mode = mode;
        event
    }

    /// One cycle at loop time `now` (s, the clock the robot's state and the tracker's samples
    /// use).
    pub fn cycle<R: Robot + ?Sized, S: PoseSource + ?Sized>(
        &mut self,
        now: f64,
        robot: &mut R,
        source: &mut S,
    ) -> CycleRecord {
        let mut rec = CycleRecord {
            t: now,
            mode: self.mode,
            event: None,
            sample_age_s: f64::NAN,
            horizon_s: 0.0,
            command_delay_s: self.command_delay,
            q_command: self.q_cmd,
            q_actual: [f64::NAN; 6],
            goal: None,
            head_speed: (0.0, 0.0),
            compute_ns: 0,
        };
        // Tracker first: samples are taken even while the robot is faulted.
        let mut event = source.latest().and_then(|s| self.take_sample(s));

        // Robot.
        let state = robot.state();
        let robot_reason = match state {
            None => Some(Reason::RobotStale),
            Some(s) if now - s.received_s > self.cfg.robot_stale_periods * self.period => {
                Some(Reason::RobotStale)
            }
            Some(s) => s.fault().map(Reason::Robot),
        };
        if let Some(s) = state {
            rec.q_actual = s.actual_q;
            self.measure_delay(s.acked_seq, s.received_s);
        }
        if let Some(r) = robot_reason {
            if !self.stop_sent {
                // Best effort: the robot may be unreachable.
                let _ = robot.stop(self.cfg.stop_decel);
                self.stop_sent = true;
            }
            self.have_cmd = false;
            self.clear_since = None;
            event = event.or(self.enter(Mode::Faulted(r)));
            rec.mode = self.mode;
            rec.event = event;
            return rec;
        }
        self.stop_sent = false;
        let Some(state) = state else { return rec };
        if !self.have_cmd {
            self.q_cmd = state.actual_q;
            self.v_cmd = [0.0; 6];
            self.have_cmd = true;
        }

        // Tracker rules and the goal.
        let mut reason = self.tracker_reason(now);
        let (v, w) = self.predictor.velocity();
        rec.head_speed = (v.norm(), w.norm());
        rec.sample_age_s = now - self.predictor.time_s();
        let mut goal_q = None;
        let mut base_from_head = None;
        if reason.is_none() {
            let head = if self.cfg.predict {
                let target_t = now + self.command_delay + self.cfg.servo.lookahead_s;
                rec.horizon_s = target_t - self.predictor.time_s();
                self.predictor.predict(target_t)
            } else {
                self.last_raw.map(|s| s.tracker_from_marker)
            };
            if let Some(tracker_from_head) = head {
                let bh = self.cfg.base_from_tracker * tracker_from_head;
                base_from_head = Some(bh);
                let goal = bh * self.cfg.head_from_coil_goal * self.coil_from_flange;
                rec.goal = Some(goal);
                let goal_coil = self.cfg.head_from_coil_goal.translation.vector;
                let gd = self.cfg.head.distance(&Point3::from(goal_coil));
                if gd < self.cfg.coil_min_distance_m {
                    reason = Some(Reason::GoalInsideHead(gd));
                } else {
                    match self.arm.ik_closest(
                        &goal,
                        &self.q_cmd,
                        &Selection::tracking(self.cfg.joint_margin_rad),
                    ) {
                        Err(_) => reason = Some(Reason::Unreachable),
                        Ok(c) => {
                            let m = self.arm.singularity(&c.joints).margin(self.arm.geometry());
                            if m < self.cfg.singularity_hold {
                                reason = Some(Reason::Singular(m));
                            } else {
                                goal_q = Some((c.joints, m));
                            }
                        }
                    }
                }
            }
        }

        // Mode.
        let mut speed_fraction = self.cfg.speed_fraction;
        let desired = match (reason, goal_q) {
            (None, Some((q, margin))) => {
                let since = *self.clear_since.get_or_insert(now);
                let ready = !matches!(self.mode, Mode::Holding(_) | Mode::Faulted(_))
                    || now - since >= self.cfg.resume_after_s;
                if ready {
                    let far = rec.goal.is_some_and(|g| {
                        (self.arm.fk_flange(&self.q_cmd).translation.vector - g.translation.vector)
                            .norm()
                            > self.cfg.servo_deviation_m
                    });
                    let next = if far {
                        Mode::Approaching
                    } else {
                        Mode::Tracking
                    };
                    event = event.or(self.enter(next));
                    if self.mode == Mode::Approaching {
                        speed_fraction = self.cfg.approach_speed_fraction;
                    }
                    if margin < self.cfg.singularity_slow {
                        speed_fraction *= (margin / self.cfg.singularity_slow).max(0.1);
                    }
                    q
                } else {
                    self.q_cmd
                }
            }
            (r, _) => {
                self.clear_since = None;
                event = event.or(self.enter(Mode::Holding(r.unwrap_or(Reason::NoTracker))));
                self.q_cmd
            }
        };

        // Limits, then the collision check on the commanded motion.
        let saved = (self.q_cmd, self.v_cmd);
        let mut q_next = self.limit(&desired, speed_fraction);
        if let Some(r) = base_from_head.and_then(|bh| self.collision(&saved.0, &q_next, &bh)) {
            // Refuse: decelerate along the last command instead.
            (self.q_cmd, self.v_cmd) = saved;
            let hold = self.q_cmd;
            q_next = self.limit(&hold, speed_fraction);
            self.clear_since = None;
            // A hold outranks a resume decided earlier in the same cycle.
            event = self.enter(Mode::Holding(r)).or(event);
        }
        self.q_cmd = q_next;
        rec.q_command = q_next;
        if let Ok(seq) = robot.servo(&q_next, &self.cfg.servo) {
            self.note_command(seq, now);
        }
        rec.mode = self.mode;
        rec.event = event;
        rec.command_delay_s = self.command_delay;
        rec
    }
}
