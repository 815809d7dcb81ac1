//! The simulated rig: both controllers and the tracker started on one stepped clock, the robots
//! moved, and both hand-eye calibrations collected and solved.

use super::*;
use mocomp_calib::plan::{PlanOptions, plan};
use mocomp_calib::procedure::MoveState;
use mocomp_calib::{Method, NoiseModel, SolveOptions, solve};
use mocomp_geom::nalgebra::Isometry3;
use mocomp_geom::{Clock, PoseSource, SteppedClock, rotation_error, translation_error};
use mocomp_igtl::client::{Client, ClientConfig, IgtlPoseSource, TimestampMode};
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use mocomp_kin::{Arm, Selection};
use mocomp_sim::TrackerSim;
use mocomp_sim::contact::Contact;
use mocomp_ur::{Robot, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimConfig, ToolLoad};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The experiment's rig in lockstep: two simulated robots (U1 with the coil, U2 with the head
/// phantom) and the tracker model serving both markers, on one stepped clock. (A live session's
/// robot and tracker are `mocomp_app::world::World`.)
pub(super) struct Rig {
    pub(super) clock: Arc<SteppedClock>,
    pub(super) period: f64,
    pub(super) sim1: Sim,
    pub(super) sim2: Sim,
    pub(super) robot1: UrRobot,
    pub(super) robot2: UrRobot,
    pub(super) arm1: Arm,
    pub(super) arm2: Arm,
    pub(super) scene: Scene,
    pub(super) tracker: TrackerSim,
    pub(super) server: Server,
    /// The head marker's client (the loop's source).
    pub(super) head_client: Client,
    /// The coil marker's client (calibration).
    pub(super) coil_client: Client,
    /// Their pose sources.
    pub(super) head_source: IgtlPoseSource,
    pub(super) coil_source: IgtlPoseSource,
    /// The tracker's time 0 on the clock (each controller's run restarts the tracker).
    pub(super) t_base: f64,
    /// Joints at the previous and this tick (for the tracker's acquisition times between).
    pub(super) q_prev: ([f64; 6], [f64; 6]),
    pub(super) q_now: ([f64; 6], [f64; 6]),
    pub(super) t_prev: f64,
    /// The phantom's head in the coil robot's base frame, for its simulated controller's
    /// contact (set before it steps, from the head robot's joints at the same tick).
    pub(super) base1_from_head: Arc<Mutex<Isometry3<f64>>>,
    /// The contact law the coil robot's simulated force sensor reads (restarted with each run).
    pub(super) sensor: Arc<Mutex<Contact>>,
    /// The contact law, for the true force each tick.
    pub(super) contact: Contact,
    /// The tracker's bump during a run: from this clock time on, the camera is moved by it.
    pub(super) bump: Option<(f64, Isometry3<f64>)>,
}

impl Rig {
    pub(super) fn start(cfg: &ExperimentConfig, scene: Scene) -> Result<Self, ExperimentError> {
        let base1_from_head = Arc::new(Mutex::new(
            scene.world_from_base1.inverse() * scene.world_from_head_rest,
        ));
        let sensor = Arc::new(Mutex::new(Contact::new(
            cfg.contact,
            cfg.head.clone(),
            cfg.coil.clone(),
            cfg.tracker.seed,
        )));
        let (sim1, sim2) = start_simulators(cfg, &scene, &base1_from_head, &sensor)?;
        let period = cfg.coil_robot.spec().series.period_s();
        let clock = Arc::new(SteppedClock::new(0.0));
        let (robot1, robot2) = connect_both(cfg, &sim1, &sim2, &clock)?;
        let (server, head_client, coil_client) = tracker_link(&clock)?;
        let q = (scene.q1_start, scene.q2_start);
        let mut w = Self {
            clock,
            period,
            sim1,
            sim2,
            robot1,
            robot2,
            arm1: Arm::new(cfg.coil_robot),
            arm2: Arm::new(cfg.head_robot),
            scene,
            tracker: TrackerSim::new(cfg.tracker, 2),
            server,
            head_source: head_client.pose_source(),
            coil_source: coil_client.pose_source(),
            head_client,
            coil_client,
            t_base: 0.0,
            q_prev: q,
            q_now: q,
            t_prev: 0.0,
            base1_from_head,
            sensor,
            contact: Contact::new(cfg.contact, cfg.head.clone(), cfg.coil.clone(), 0),
            bump: None,
        };
        // One step so the states carry the stepped clock's time.
        w.advance()?;
        Ok(w)
    }

    pub(super) fn world_from_e1(&self, q1: &[f64; 6]) -> Isometry3<f64> {
        self.scene.world_from_base1 * self.arm1.fk_flange(q1)
    }

    pub(super) fn world_from_e2(&self, q2: &[f64; 6]) -> Isometry3<f64> {
        self.arm2.fk_flange(q2)
    }

    /// The tracker acquires what is due and sends what its latency releases; returns when both
    /// clients have received it.
    pub(super) fn track(&mut self) -> Result<(), ExperimentError> {
        let now = self.clock.now_s();
        let base = self.t_base;
        let (t0, t1) = (self.t_prev - base, now - base);
        let (qa, qb) = (self.q_prev, self.q_now);
        let lerp = |a: &[f64; 6], b: &[f64; 6], t: f64| {
            let s = if t1 > t0 {
                ((t - t0) / (t1 - t0)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let mut q = [0.0; 6];
            for i in 0..6 {
                q[i] = a[i] + (b[i] - a[i]) * s;
            }
            q
        };
        let unbumped = self.scene.world_from_tracker.inverse();
        let bump = self.bump;
        let (arm1, arm2, scene) = (self.arm1, self.arm2, self.scene);
        let mut truth = |marker: usize, t: f64| {
            // The camera as it stood when the sample was acquired.
            let tracker_from_world = match bump {
                Some((at, b)) if t + base >= at => (scene.world_from_tracker * b).inverse(),
                _ => unbumped,
            };
            Some(match marker {
                0 => {
                    tracker_from_world * arm2.fk_flange(&lerp(&qa.1, &qb.1, t)) * scene.e2_from_head
                }
                _ => {
                    tracker_from_world
                        * scene.world_from_base1
                        * arm1.fk_flange(&lerp(&qa.0, &qb.0, t))
                        * scene.e1_from_coil
                }
            })
        };
        let before = (
            self.head_client.counters().transforms,
            self.coil_client.counters().transforms,
        );
        let mut sent = 0u64;
        let server = &self.server;
        self.tracker.step(now - base, &mut truth, &mut |o| {
            let device = if o.marker == 0 {
                HEAD_DEVICE
            } else {
                COIL_DEVICE
            };
            let ts = Timestamp::from_secs_f64(o.acquired_s + base + EPOCH_S);
            if let Ok(m) = Message::transform(device, &o.tracker_from_marker, ts) {
                let status = if o.valid { "OK" } else { "INVALID" };
                server.send(&m.with_metadata(vec![MetaEntry::text("TransformStatus", status)]));
                sent += 1;
            }
        });
        if sent > 0 {
            let (h, c) = (&self.head_client, &self.coil_client);
            spin("tracker messages", || {
                h.counters().transforms >= before.0 + sent
                    && c.counters().transforms >= before.1 + sent
            })?;
        }
        Ok(())
    }

    /// Waits until both simulators have taken this tick's commands, advances the clock one
    /// period, steps both and waits for their new states.
    pub(super) fn advance(&mut self) -> Result<(), ExperimentError> {
        let n = (self.robot1.state_count(), self.robot2.state_count());
        self.t_prev = self.clock.now_s();
        self.clock.advance(self.period);
        // The head robot first: the coil robot's contact needs where the head is at this tick.
        self.sim2.step();
        let q2 = self.sim2.with(|c| c.q());
        let base1_from_head = self.scene.world_from_base1.inverse()
            * self.arm2.fk_flange(&q2)
            * self.scene.e2_from_head;
        *self
            .base1_from_head
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner) = base1_from_head;
        self.sim1.step();
        let (r1, r2) = (&self.robot1, &self.robot2);
        spin("the robots' states", || {
            r1.state_count() > n.0 && r2.state_count() > n.1
        })?;
        self.q_prev = self.q_now;
        if let (Some(a), Some(b)) = (self.robot1.state(), self.robot2.state()) {
            self.q_now = (a.actual_q, b.actual_q);
        }
        Ok(())
    }

    /// Sends a command on a robot and waits until its simulator has it.
    pub(super) fn sent(
        sim: &Sim,
        f: impl FnOnce() -> Result<(), mocomp_robot::RobotError>,
    ) -> Result<(), ExperimentError> {
        let inputs = sim.stats().inputs;
        f().map_err(|e| io("commanding a robot", e))?;
        spin("a command to arrive", || sim.stats().inputs > inputs)
    }

    /// Moves one robot (U1 if `coil`) to `q` with movej while the other keeps still, ticking
    /// until the move has arrived ([`mocomp_calib::procedure::move_state`]).
    pub(super) fn move_to(&mut self, coil: bool, q: &[f64; 6]) -> Result<(), ExperimentError> {
        let start = self.clock.now_s();
        let mut seq: Option<i32> = None;
        loop {
            self.track()?;
            let (mover, other, sim_m, sim_o) = if coil {
                (&mut self.robot1, &mut self.robot2, &self.sim1, &self.sim2)
            } else {
                (&mut self.robot2, &mut self.robot1, &self.sim2, &self.sim1)
            };
            let sent = match seq {
                Some(n) => {
                    Self::sent(sim_m, || mover.keep_alive())?;
                    n
                }
                None => {
                    let mut n = 0;
                    Self::sent(sim_m, || {
                        n = mover.move_joints(q, 2.0, 4.0)?;
                        Ok(())
                    })?;
                    seq = Some(n);
                    n
                }
            };
            Self::sent(sim_o, || other.keep_alive())?;
            self.advance()?;
            let s = if coil {
                self.robot1.state()
            } else {
                self.robot2.state()
            };
            if let Some(s) = s {
                if let Some(f) = s.fault() {
                    return Err(io("a calibration move", f.to_string()));
                }
                match mocomp_calib::procedure::move_state(&s, q, sent) {
                    MoveState::Arrived => return Ok(()),
                    MoveState::Away => {
                        return Err(io(
                            "a calibration move",
                            "the move ended away from its target",
                        ));
                    }
                    MoveState::Moving => {}
                }
            }
            if self.clock.now_s() - start > 30.0 {
                return Err(ExperimentError::Timeout {
                    what: "a calibration move",
                    seen: None,
                });
            }
        }
    }

    /// Ticks for `seconds` with both robots still.
    pub(super) fn idle(&mut self, seconds: f64) -> Result<(), ExperimentError> {
        let end = self.clock.now_s() + seconds;
        while self.clock.now_s() < end - 1e-9 {
            self.track()?;
            Self::sent(&self.sim1, || self.robot1.keep_alive())?;
            Self::sent(&self.sim2, || self.robot2.keep_alive())?;
            self.advance()?;
        }
        Ok(())
    }

    /// Hand-eye calibration of one robot against the tracker: the planner's poses around its
    /// start, `samples` averaged at each, solved with the refined method.
    pub(super) fn calibrate(
        &mut self,
        coil: bool,
        cfg: &ExperimentConfig,
        progress: &mut dyn FnMut(Phase, f64),
    ) -> Result<CalibrationResult, ExperimentError> {
        let (arm, q0, name, phase) = if coil {
            (
                self.arm1,
                self.scene.q1_start,
                "the coil robot",
                Phase::CalibratingCoilRobot,
            )
        } else {
            (
                self.arm2,
                self.scene.q2_start,
                "the head robot",
                Phase::CalibratingHeadRobot,
            )
        };
        let calib_err = |detail: String| ExperimentError::Calibration {
            robot: name,
            detail,
        };
        if !coil {
            // The phantom turns and shifts around its start: the coil must not be in its way
            // (it was, unseen, until the coil's contact with the scalp was simulated).
            self.coil_clear_of_head()
                .map_err(|e| calib_err(format!("moving the coil robot clear: {e}")))?;
        }
        // Around the start, backed off along the flange axis (the coil away from the head).
        let center = arm.fk_flange(&q0) * calibration_backoff();
        let current = arm
            .ik_closest(&center, &q0, &Selection::tracking(0.1))
            .map_err(|e| calib_err(format!("the centre pose: {e}")))?
            .joints;
        let mut o = PlanOptions::new(cfg.calibration_poses, center, current);
        o.translation_spread_m = 0.06;
        o.rotation_range_rad = (12f64.to_radians(), 30f64.to_radians());
        let poses = plan(&arm, &o).map_err(|e| calib_err(e.to_string()))?;
        let n = poses.len() as f64;
        let mut station = CalibrationStation { world: self, coil };
        let got = mocomp_calib::procedure::collect(
            &mut station,
            &arm,
            &poses,
            &q0,
            0.05,
            cfg.calibration_samples,
            &mut |i, _| progress(phase, (i + 1) as f64 / n),
        )?;
        if !got.missed.is_empty() {
            return Err(calib_err(format!(
                "no marker samples at pose(s) {:?}",
                got.missed
            )));
        }
        let pairs = got.pairs;
        let noise = NoiseModel {
            tracker_translation_m: cfg.tracker.noise_m.max(1e-6),
            tracker_rotation_rad: cfg.tracker.noise_rad.max(1e-6),
            robot_translation_m: 1e-5,
            robot_rotation_rad: 1e-5,
        };
        let c = solve(
            &pairs,
            &SolveOptions {
                method: Method::Refined,
                noise,
                reject_outliers: true,
            },
        )
        .map_err(|e| calib_err(e.to_string()))?;
        let (true_x, true_y) = if coil {
            (
                self.scene.e1_from_coil,
                self.scene.world_from_base1.inverse() * self.scene.world_from_tracker,
            )
        } else {
            (self.scene.e2_from_head, self.scene.world_from_tracker)
        };
        let err = |a: &Isometry3<f64>, b: &Isometry3<f64>| {
            (translation_error(a, b), rotation_error(a, b))
        };
        Ok(CalibrationResult {
            flange_from_marker: c.flange_from_marker,
            base_from_tracker: c.base_from_tracker,
            residual: (c.rms_mm * 1e-3, c.rms_deg.to_radians()),
            x_error: err(&c.flange_from_marker, &true_x),
            y_error: err(&c.base_from_tracker, &true_y),
            pairs: pairs.len(),
        })
    }
}

/// One robot of the experiment's world as a calibration station, in lockstep.
pub(super) struct CalibrationStation<'a> {
    pub(super) world: &'a mut Rig,
    /// U1 (the coil robot) if true, else U2.
    pub(super) coil: bool,
}

impl mocomp_calib::procedure::Station for CalibrationStation<'_> {
    type Error = ExperimentError;

    fn move_to(&mut self, q: &[f64; 6]) -> Result<(), ExperimentError> {
        self.world.move_to(self.coil, q)
    }

    fn settle(&mut self, seconds: f64) -> Result<(), ExperimentError> {
        self.world.idle(seconds)
    }

    /// The joints are the simulator's at the first sample (the arm is still); a marker unseen
    /// for 5 s of simulated time is not seen.
    fn measure(
        &mut self,
        samples: usize,
    ) -> Result<Option<mocomp_calib::procedure::Measurement>, ExperimentError> {
        let w = &mut *self.world;
        let after = w.clock.now_s();
        let mut seen = Vec::new();
        let mut qs = Vec::new();
        while seen.len() < samples {
            w.idle(w.period)?;
            let s = if self.coil {
                w.coil_source.latest()
            } else {
                w.head_source.latest()
            };
            if let Some(s) = s
                && s.valid
                && s.acquired_s > after
            {
                seen.push(s.tracker_from_marker);
                qs.push(if self.coil { w.q_now.0 } else { w.q_now.1 });
            }
            if w.clock.now_s() - after > 5.0 {
                return Ok(None);
            }
        }
        let Some(&q) = qs.first() else {
            return Ok(None);
        };
        let marker =
            mocomp_geom::average(&seen, None).map_err(|e| io("averaging the marker samples", e))?;
        Ok(Some((q, marker)))
    }
}

/// Both robots' simulated controllers on the stepped clock, the coil robot's with the contact
/// law's wrench on its tool.
fn start_simulators(
    cfg: &ExperimentConfig,
    scene: &Scene,
    base1_from_head: &Arc<Mutex<Isometry3<f64>>>,
    sensor: &Arc<Mutex<Contact>>,
) -> Result<(Sim, Sim), ExperimentError> {
    let mut c1 = ControllerConfig::new(cfg.coil_robot);
    c1.initial_q = scene.q1_start;
    let (head, law) = (Arc::clone(base1_from_head), Arc::clone(sensor));
    let tcp_from_coil = scene.e1_from_coil;
    c1.tool_load = Some(ToolLoad::new(move |t, base_from_tcp| {
        let base_from_head = *head
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        law.lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .wrench(t, &(base_from_tcp * tcp_from_coil), &base_from_head)
    }));
    let mut c2 = ControllerConfig::new(cfg.head_robot);
    c2.initial_q = scene.q2_start;
    let mut s1 = SimConfig::new(c1, cfg.coil_host);
    s1.clock = mocomp_ursim::SimClock::Stepped;
    let mut s2 = SimConfig::new(c2, cfg.head_host);
    s2.clock = mocomp_ursim::SimClock::Stepped;
    let sim1 = Sim::start(s1).map_err(|e| io("starting the coil robot's simulator", e))?;
    let sim2 = Sim::start(s2).map_err(|e| io("starting the head robot's simulator", e))?;
    Ok((sim1, sim2))
}

/// mocomp's RTDE client connected to both simulators.
fn connect_both(
    cfg: &ExperimentConfig,
    sim1: &Sim,
    sim2: &Sim,
    clock: &Arc<SteppedClock>,
) -> Result<(UrRobot, UrRobot), ExperimentError> {
    let period = cfg.coil_robot.spec().series.period_s();
    // Connect both while stepping the simulators at most at real time (the client feeds the
    // program's watchdog on the machine's clock, so a faster simulator would stop a client
    // that a busy machine delayed for a few milliseconds; the clock stays at 0 meanwhile).
    // Both at once, and a simulator stops stepping once its robot is connected: a connected
    // robot whose program is not fed would stop on its watchdog.
    let done = [AtomicBool::new(false), AtomicBool::new(false)];
    let slowest = period.max(cfg.head_robot.spec().series.period_s());
    let (r1, r2) = std::thread::scope(|s| {
        s.spawn(|| {
            while !(done[0].load(Ordering::Relaxed) && done[1].load(Ordering::Relaxed)) {
                if !done[0].load(Ordering::Relaxed) {
                    sim1.step();
                }
                if !done[1].load(Ordering::Relaxed) {
                    sim2.step();
                }
                std::thread::sleep(Duration::from_secs_f64(slowest));
            }
        });
        let c: Arc<dyn Clock> = clock.clone();
        let c2 = Arc::clone(&c);
        let h2 = s.spawn(|| {
            let r = UrRobot::connect(sim2.ur_config(), c2);
            done[1].store(true, Ordering::Relaxed);
            r
        });
        let r1 = UrRobot::connect(sim1.ur_config(), c);
        done[0].store(true, Ordering::Relaxed);
        let r2 = h2.join();
        done[1].store(true, Ordering::Relaxed);
        (r1, r2)
    });
    // A failed connection says what the simulator saw.
    let events = |sim: &Sim| {
        let (ev, _) = sim.with(|c| c.events());
        ev.iter()
            .map(|e| format!("{:.3} s {}", e.time_s, e.text))
            .collect::<Vec<_>>()
            .join("; ")
    };
    let robot1 = r1.map_err(|e| ExperimentError::Io {
        what: "connecting to the coil robot",
        simulators: Some(events(sim1)),
        source: Box::new(e),
    })?;
    let r2 = r2.map_err(|_| io("connecting to the head robot", "the thread panicked"))?;
    let robot2 = r2.map_err(|e| ExperimentError::Io {
        what: "connecting to the head robot",
        simulators: Some(events(sim2)),
        source: Box::new(e),
    })?;
    Ok((robot1, robot2))
}

/// The tracker's OpenIGTLink server and mocomp's clients of it, one per marker.
fn tracker_link(clock: &Arc<SteppedClock>) -> Result<(Server, Client, Client), ExperimentError> {
    let server = Server::bind("127.0.0.1:0", ServerConfig::default())
        .map_err(|e| io("starting the tracker's OpenIGTLink server", e))?;
    let client = |device: &str| {
        let mut c = ClientConfig::new(&server.local_addr().to_string());
        c.device = Some(device.to_string());
        c.timestamps = TimestampMode::Known(-EPOCH_S);
        Client::start(c, clock.clone())
    };
    let head_client = client(HEAD_DEVICE);
    let coil_client = client(COIL_DEVICE);
    // A failure says how far each side got, so a hung link names its side.
    let seen = || {
        let side = |name: &str, c: &Client| {
            let n = c.counters();
            format!(
                "{name} client: {} connections, {} failed, last error: {}",
                n.connections,
                n.connect_failures,
                c.last_error().unwrap_or_else(|| "none".into())
            )
        };
        Some(format!(
            "the server accepted {} and holds {}; {}; {}",
            server.counters().accepted,
            server.client_count(),
            side("head", &head_client),
            side("coil", &coil_client)
        ))
    };
    spin_seen(
        "the tracker clients to connect",
        || server.client_count() == 2,
        seen,
    )?;
    Ok((server, head_client, coil_client))
}
