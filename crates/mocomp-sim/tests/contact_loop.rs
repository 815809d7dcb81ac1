#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code
//! Closed-loop contact tests on the stepped clock: the compensation loop drives a simulated UR3e
//! (mocomp-ursim, over TCP through the real client) whose tool meets the scalp through the
//! contact law ([`mocomp_sim::contact`]), read back as the robot's `actual_TCP_force`; the head
//! follows a scripted motion seen by a 60 Hz tracker with 20 ms latency. Each cycle the true
//! force (the law's springs at the measured coil pose) is recorded, which is what the patient
//! feels, not what the loop read.

use mocomp_control::{Compensator, CycleRecord, Event, HeadModel, LoopConfig, Mode, Reason};
use mocomp_geom::nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use mocomp_geom::{Clock, SteppedClock};
use mocomp_kin::{Arm, Model, Selection};
use mocomp_sim::contact::{Contact, ContactParams, SIMULATED_SENSOR_NOISE_N};
use mocomp_testkit::mem::ScriptedPoses;
use mocomp_testkit::scene::{base_from_tracker, flange_from_coil, head_from_coil_goal, head_rest};
use mocomp_testkit::spin_until;
use mocomp_ur::{Robot, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimConfig, ToolLoad};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::sync::{Arc, Mutex};

const PERIOD: f64 = 0.002;

/// `base_from_head` at a time.
type Motion = Arc<dyn Fn(f64) -> Isometry3<f64> + Send + Sync>;

/// What the simulated sensor reports.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Sensor {
    /// The contact law's wrench with noise.
    Live,
    /// Its last reading, forever (a stale sensor: a frozen driver, a dead link).
    Frozen,
    /// This force along base z, with noise (a reading at the end of the range).
    Fixed(f64),
}

struct Scenario {
    motion: Motion,
    seconds: f64,
    tune: fn(&mut LoopConfig),
    /// The scalp as the contact law sees it: the loop's head model, or another (a wrong model).
    true_head_grow_m: f64,
    /// The sensor's behaviour from a time on.
    sensor_from: Option<(f64, Sensor)>,
    /// The tracker loses the head in this interval (its samples marked invalid).
    dropout: Option<(f64, f64)>,
}

impl Scenario {
    fn new(motion: Motion, seconds: f64) -> Self {
        Self {
            motion,
            seconds,
            tune: |_| {},
            true_head_grow_m: 0.0,
            sensor_from: None,
            dropout: None,
        }
    }
}

struct Outcome {
    records: Vec<CycleRecord>,
    /// (t, the true force on the scalp N, the coil's true clearance m) per cycle.
    truth: Vec<(f64, f64, f64)>,
    /// What the simulated controller logged.
    simulator: Vec<String>,
}

impl Outcome {
    /// Whether the controller's own force limit stopped the arm.
    fn protective_stops(&self) -> Vec<&String> {
        self.simulator
            .iter()
            .filter(|e| e.contains("protective"))
            .collect()
    }

    fn events(&self) -> Vec<(f64, Event)> {
        self.records
            .iter()
            .filter_map(|r| r.event.map(|e| (r.t, e)))
            .collect()
    }

    fn force_between(&self, from: f64, to: f64) -> (f64, f64, f64) {
        let f: Vec<f64> = self
            .truth
            .iter()
            .filter(|x| x.0 >= from && x.0 < to)
            .map(|x| x.1)
            .collect();
        let mean = f.iter().sum::<f64>() / f.len() as f64;
        let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = f.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, mean, hi)
    }

    /// The longest stretch the true force stayed above `level`, s.
    fn longest_above(&self, level: f64) -> f64 {
        let (mut longest, mut since) = (0.0f64, None);
        for &(t, f, _) in &self.truth {
            if f > level {
                let s = *since.get_or_insert(t);
                longest = longest.max(t - s + PERIOD);
            } else {
                since = None;
            }
        }
        longest
    }
}

/// The controller's own force limit (150 N) never had to stop the arm.
fn no_protective_stop(o: &Outcome) {
    let stops = o.protective_stops();
    if !stops.is_empty() {
        for x in o.truth.iter().filter(|x| x.1 > 5.0).take(60) {
            eprintln!("{:.3} s {:.1} N clearance {:.2} mm", x.0, x.1, x.2 * 1e3);
        }
    }
    assert!(
        stops.is_empty(),
        "the controller protective-stopped: {stops:?}"
    );
}

fn loop_config() -> LoopConfig {
    let mut cfg = LoopConfig::new(
        base_from_tracker(),
        flange_from_coil(),
        head_from_coil_goal(),
        PERIOD,
    );
    cfg.params.force_sensing = true;
    cfg
}

fn contact_mode(cfg: &mut LoopConfig) {
    cfg.params.contact_mode = true;
}

fn run(sc: Scenario) -> Outcome {
    let arm = Arm::new(Model::Ur3e);
    let cfg0 = loop_config();
    let mut cfg = cfg0.clone();
    (sc.tune)(&mut cfg);
    let motion = sc.motion;
    let start_goal = motion(0.0) * head_from_coil_goal() * flange_from_coil().inverse();
    let q0 = arm
        .ik_closest(
            &start_goal,
            &[0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
            &Selection::tracking(0.05),
        )
        .unwrap()
        .joints;
    // The scalp the contact law sees.
    let e = cfg.head.as_ellipsoid().unwrap();
    let true_head = HeadModel::ellipsoid(
        *e.head_from_ellipsoid(),
        e.radii() + Vector3::from_element(sc.true_head_grow_m),
    )
    .unwrap();
    let contact = |seed| {
        Contact::new(
            ContactParams {
                noise_n: SIMULATED_SENSOR_NOISE_N,
                ..ContactParams::default()
            },
            true_head.clone(),
            cfg.coil.clone(),
            seed,
        )
    };
    let truth_law = contact(1);
    // What the simulated controller's tool load reads: the head now, the sensor's behaviour.
    let head_now = Arc::new(Mutex::new(motion(0.0)));
    let sensor = Arc::new(Mutex::new(Sensor::Live));
    let mut law = contact(7);
    let mut noise = contact(11);
    let (h, s) = (Arc::clone(&head_now), Arc::clone(&sensor));
    let mut last = [0.0; 6];
    let coil_from_tcp = flange_from_coil();
    let mut ctrl = ControllerConfig::new(Model::Ur3e);
    ctrl.initial_q = q0;
    ctrl.tool_load = Some(ToolLoad::new(move |t, base_from_tcp| {
        let base_from_head = *h.lock().unwrap();
        let base_from_coil = base_from_tcp * coil_from_tcp;
        let w = law.wrench(t, &base_from_coil, &base_from_head);
        let reading = match *s.lock().unwrap() {
            Sensor::Live => w,
            Sensor::Frozen => last,
            Sensor::Fixed(fz) => {
                // Noise from a coil far from any head: the sensor's own.
                let far = Isometry3::translation(10.0, 0.0, 0.0);
                let n = noise.wrench(t, &far, &Isometry3::identity());
                [n[0], n[1], fz + n[2], 0.0, 0.0, 0.0]
            }
        };
        last = reading;
        reading
    }));
    let sim = Sim::start(SimConfig::stepped_local(ctrl)).unwrap();
    let clock = Arc::new(SteppedClock::new(0.0));
    let ucfg = sim.ur_config();
    let mut robot = sim
        .stepping_in_real_time(|| UrRobot::connect(ucfg, clock.clone()))
        .unwrap();
    let mut comp = Compensator::new(cfg, arm, PERIOD);
    let m = Arc::clone(&motion);
    let tracker_from_base = base_from_tracker().inverse();
    // A tracker's noise (0.05 mm, 0.5 mrad, seeded): a still head must not look frozen.
    let dropout = sc.dropout;
    let rng = std::cell::RefCell::new(ChaCha8Rng::seed_from_u64(5));
    let normal = Normal::new(0.0, 1.0).unwrap();
    let mut tracker = ScriptedPoses::new(
        60.0,
        0.02,
        Box::new(move |t| {
            if dropout.is_some_and(|(a, b)| t >= a && t < b) {
                return None;
            }
            let mut r = rng.borrow_mut();
            let mut g = || normal.sample(&mut *r);
            let dp = Vector3::new(g(), g(), g()) * 5e-5;
            let dr = Vector3::new(g(), g(), g()) * 5e-4;
            let truth = tracker_from_base * m(t);
            // About the marker, as a tracker's error is.
            Some(Isometry3::from_parts(
                Translation3::from(truth.translation.vector + dp),
                UnitQuaternion::from_scaled_axis(dr) * truth.rotation,
            ))
        }),
    );
    let n = robot.state_count();
    robot.keep_alive().unwrap();
    sim.step();
    spin_until("the first state", || robot.state_count() > n);
    let cycles = (sc.seconds / PERIOD).round() as usize;
    let mut records = Vec::with_capacity(cycles);
    let mut truth = Vec::with_capacity(cycles);
    for _ in 0..cycles {
        let now = clock.now_s();
        if let Some((t, behaviour)) = sc.sensor_from
            && now >= t
        {
            *sensor.lock().unwrap() = behaviour;
        }
        tracker.now = now;
        let inputs = sim.stats().inputs;
        let rec = comp.cycle(now, &mut robot, &mut tracker);
        if matches!(rec.mode, Mode::Faulted(_)) {
            robot.keep_alive().ok();
        }
        spin_until("the command", || sim.stats().inputs > inputs);
        let states = robot.state_count();
        clock.advance(PERIOD);
        let t = clock.now_s();
        *head_now.lock().unwrap() = motion(t);
        sim.step();
        spin_until("the next state", || robot.state_count() > states);
        let s = robot.state().unwrap();
        let head_from_coil = motion(t).inverse() * arm.fk_flange(&s.actual_q) * flange_from_coil();
        truth.push((
            t,
            truth_law.force_n(&head_from_coil),
            cfg0.coil.distance(&true_head, &head_from_coil),
        ));
        records.push(rec);
    }
    let faults = sim.with(|c| c.event_texts());
    Outcome {
        records,
        truth,
        simulator: faults,
    }
}

/// The coil's approach axis in the base frame with the head at rest (into the head).
fn axis_at_rest() -> Vector3<f64> {
    (head_rest() * head_from_coil_goal()).rotation * Vector3::z()
}

/// A slow drift: 3 mm/s along the coil's axis and across it, and 1°/s of yaw, from 1 s on.
fn drift() -> Motion {
    Arc::new(|t| {
        let s = (t - 1.0).max(0.0);
        let v = axis_at_rest() * 0.002 + Vector3::new(0.002, 0.0, 0.0);
        Isometry3::translation(v.x * s, v.y * s, v.z * s)
            * head_rest()
            * Isometry3::rotation(Vector3::new(0.0, 0.0, (1.0f64).to_radians() * s))
    })
}

/// Nods as `examples/demo-nods.toml`'s patient: pitch ±5° at 0.5 Hz (16°/s) with ±10 mm of
/// translation (31 mm/s), ramped in from 3 s.
fn nods() -> Motion {
    Arc::new(|t| {
        let w = std::f64::consts::PI; // 0.5 Hz
        let t = (t - 3.0).max(0.0);
        let ramp = (t / 1.0).min(1.0);
        let ramp = ramp * ramp * (3.0 - 2.0 * ramp);
        let pitch = (5.0f64).to_radians() * ramp * (w * t).sin();
        let x = 0.01 * ramp * (w * t).sin();
        head_rest() * Isometry3::new(Vector3::new(x, 0.0, 0.0), Vector3::new(pitch, 0.0, 0.0))
    })
}

#[test]
fn contact_mode_settles_on_the_set_force_and_holds_it_through_a_slow_drift() {
    let mut sc = Scenario::new(drift(), 7.0);
    sc.tune = contact_mode;
    let o = run(sc);
    let set = LoopConfig::new(
        Isometry3::identity(),
        Isometry3::identity(),
        Isometry3::identity(),
        PERIOD,
    )
    .params
    .contact_force_n;
    let (lo, mean, hi) = o.force_between(2.5, 7.0);
    eprintln!(
        "contact mode, slow drift: true force {lo:.2}..{hi:.2} N (mean {mean:.2}) for a set {set} N; events {:?}",
        o.events()
    );
    no_protective_stop(&o);
    assert!(
        (lo - set).abs() <= 1.0 && (hi - set).abs() <= 1.0,
        "{lo}..{hi} N"
    );
    // It pressed in from the goal's 3 mm standoff, and no force rule fired.
    let press = o.records.last().unwrap().press_m;
    assert!(press > 0.003, "{press}");
    assert!(
        !o.events()
            .iter()
            .any(|(_, e)| matches!(e, Event::Retreat(_) | Event::Hold(_))),
        "{:?}",
        o.events()
    );
}

#[test]
fn contact_mode_keeps_the_force_in_a_band_while_the_head_nods() {
    let mut sc = Scenario::new(nods(), 9.0);
    sc.tune = contact_mode;
    let o = run(sc);
    let (lo, mean, hi) = o.force_between(4.0, 9.0);
    eprintln!(
        "contact mode, nods: true force {lo:.2}..{hi:.2} N (mean {mean:.2}); events {:?}",
        o.events()
    );
    no_protective_stop(&o);
    // The band stated: the set 3 N ± 1.5 N (measured: about 2.3..3.4 N).
    assert!(lo >= 1.5 && hi <= 4.5, "{lo}..{hi} N");
}

#[test]
fn a_head_pushed_into_the_coil_at_90_mm_s_never_holds_the_force_over_the_limit() {
    // In contact, then the head moves 30 mm towards the coil (against its axis) at 90 mm/s,
    // reached within 20 ms.
    let m: Motion = Arc::new(|t| {
        let a = 0.09 / 0.02; // m/s²
        let s = (t - 3.0).max(0.0);
        let d = if s < 0.02 {
            0.5 * a * s * s
        } else {
            (0.5 * a * 0.02 * 0.02 + 0.09 * (s - 0.02)).min(0.03)
        };
        let v = -axis_at_rest() * d;
        Isometry3::translation(v.x, v.y, v.z) * head_rest()
    });
    let mut sc = Scenario::new(m, 5.0);
    sc.tune = contact_mode;
    let o = run(sc);
    let p = loop_config().params;
    let (_, _, peak) = o.force_between(3.0, 5.0);
    let over = o.longest_above(p.max_contact_force_n);
    let warned = o.longest_above(p.contact_warning_force_n);
    eprintln!(
        "push at 90 mm/s: peak {peak:.1} N, over {} N for {over:.3} s, over {} N for {warned:.3} s; events {:?}",
        p.max_contact_force_n,
        p.contact_warning_force_n,
        o.events()
    );
    no_protective_stop(&o);
    // The rule: above the limit the coil retreats at once (what it allows is the servo's lag);
    // above the warning level it may stay for contact_warning_s.
    assert!(over <= 0.05, "{over} s over the limit");
    assert!(
        warned <= p.contact_warning_s + 0.05,
        "{warned} s over the warning level"
    );
}

#[test]
fn a_head_model_too_small_is_felt_and_the_coil_eases_off_to_a_light_touch() {
    // The true scalp is 8 mm outside the loop's model: at the goal's 3 mm standoff the coil
    // presses 5 mm into it (about 18 N here), which only the force shows.
    let mut sc = Scenario::new(Arc::new(|_| head_rest()), 4.0);
    sc.true_head_grow_m = 0.008;
    let o = run(sc);
    let ev = o.events();
    let p = loop_config().params;
    let (lo, mean, hi) = o.force_between(2.0, 4.0);
    eprintln!(
        "model 8 mm small: starts at {:.1} N, then {lo:.2}..{hi:.2} N (mean {mean:.2}); events {ev:?}",
        o.truth[0].1
    );
    no_protective_stop(&o);
    assert!(o.truth[0].1 > p.contact_warning_force_n, "{}", o.truth[0].1);
    // Eased off before the warning level's time ran out, to the light touch, and stays there.
    assert!(o.longest_above(p.contact_warning_force_n) < p.contact_warning_s);
    assert!(
        (lo - p.contact_force_n).abs() <= 1.0 && (hi - p.contact_force_n).abs() <= 1.0,
        "{lo}..{hi} N"
    );
}

#[test]
fn a_head_pushed_into_the_coil_during_a_tracker_dropout_is_felt_and_the_coil_retreats() {
    // In contact; at 3 s the tracker loses the head for 0.35 s while it moves 15 mm towards
    // the coil at 50 mm/s. The loop coasts on a still head: only the force shows the push.
    let m: Motion = Arc::new(|t| {
        let d = 0.05 * (t - 3.0).clamp(0.0, 0.3);
        let v = -axis_at_rest() * d;
        Isometry3::translation(v.x, v.y, v.z) * head_rest()
    });
    let mut sc = Scenario::new(m, 9.0);
    sc.tune = contact_mode;
    sc.dropout = Some((3.0, 3.35));
    let o = run(sc);
    let ev = o.events();
    let p = loop_config().params;
    let (_, _, peak) = o.force_between(3.0, 4.0);
    let (lo, mean, hi) = o.force_between(8.0, 9.0);
    eprintln!(
        "push in a dropout: peak {peak:.1} N, over {} N for {:.3} s; back in contact {lo:.2}..{hi:.2} N (mean {mean:.2}); events {ev:?}",
        p.max_contact_force_n,
        o.longest_above(p.max_contact_force_n)
    );
    no_protective_stop(&o);
    let r = ev
        .iter()
        .find(|(_, e)| {
            matches!(
                e,
                Event::Retreat(Reason::ContactForce(_) | Reason::ForceSaturated(_))
            )
        })
        .expect("a retreat for the force");
    assert!(r.0 > 3.0 && r.0 < 3.35, "{}", r.0);
    assert!(o.longest_above(p.max_contact_force_n) <= 0.05);
    // Back on the scalp at the set force once the head is seen again.
    assert!((lo - p.contact_force_n).abs() <= 1.0 && (hi - p.contact_force_n).abs() <= 1.0);
}

fn sensor_fault(behaviour: Sensor) -> (Outcome, f64) {
    let mut sc = Scenario::new(Arc::new(|_| head_rest()), 5.0);
    sc.tune = contact_mode;
    sc.sensor_from = Some((3.0, behaviour));
    (run(sc), 3.0)
}

#[test]
fn a_stale_force_sensor_takes_the_coil_off_the_scalp_with_its_reason() {
    let (o, at) = sensor_fault(Sensor::Frozen);
    let ev = o.events();
    eprintln!("stale sensor: {ev:?}");
    no_protective_stop(&o);
    let p = loop_config().params;
    let r = ev
        .iter()
        .find(|(_, e)| matches!(e, Event::Retreat(Reason::ForceSensorStale(_))))
        .expect("a retreat for a stale sensor");
    assert!(
        r.0 > at + p.force_stale_s && r.0 < at + p.force_stale_s + 0.02,
        "{}",
        r.0
    );
    // Still retreated at the end (the sensor stays stale), off the scalp by the retreat.
    let last = o.records.last().unwrap();
    assert!(
        matches!(last.mode, Mode::Retreating(Reason::ForceSensorStale(_))),
        "{:?}",
        last.mode
    );
    let end = o.truth.last().unwrap();
    assert!(end.1 == 0.0 && end.2 > 0.02, "{end:?}");
}

#[test]
fn a_saturated_force_sensor_takes_the_coil_off_the_scalp_with_its_reason() {
    // A UR3e's sensor ends at 30 N.
    let (o, at) = sensor_fault(Sensor::Fixed(-31.0));
    let ev = o.events();
    eprintln!("saturated sensor: {ev:?}");
    no_protective_stop(&o);
    let r = ev
        .iter()
        .find(|(_, e)| matches!(e, Event::Retreat(Reason::ForceSaturated(_))))
        .expect("a retreat for a saturated sensor");
    assert!(r.0 >= at && r.0 < at + 0.01, "{}", r.0);
    let end = o.truth.last().unwrap();
    assert!(end.1 == 0.0 && end.2 > 0.02, "{end:?}");
}
