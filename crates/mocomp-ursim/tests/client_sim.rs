#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! Our client (`mocomp-ur`) against our simulator (`mocomp-ursim`), over TCP on loopback.

use mocomp_geom::{Clock, MonotonicClock, translation_error};
use mocomp_kin::{Arm, Model};
use mocomp_robot::{RobotError, RobotFault, RuntimeState, SafetyMode};
use mocomp_testkit::{spin_until, wait_until};
use mocomp_ur::connection::RtdeConnection;
use mocomp_ur::{Robot, ServoParams, UrConfig, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimClock, SimConfig};
use std::sync::Arc;
use std::time::Duration;

fn sim(model: Model, clock: SimClock) -> Sim {
    let mut c = SimConfig::stepped_local(ControllerConfig::new(model));
    c.clock = clock;
    Sim::start(c).unwrap()
}

/// The client's configuration for `sim`, its program's watchdog allowing 500 ms of silence
/// (2 Hz). These tests keep the program alive from the test's own thread, an ordinary one that
/// a loaded machine (or, in a root run, the real-time threads beside it) may not schedule for
/// the default's 50 ms: the move test timed out so beside `stress-ng`, its program stopped
/// under it. The watchdog's own tests set theirs.
fn config_for(sim: &Sim) -> UrConfig {
    let mut cfg = sim.ur_config();
    cfg.watchdog_hz = 2.0;
    cfg
}

fn connect(sim: &Sim) -> UrRobot {
    UrRobot::connect(config_for(sim), Arc::new(MonotonicClock::new())).unwrap()
}

/// Steps a stepped simulator in the background while `f` runs (connecting needs state packages).
fn pumped<T>(sim: &Sim, f: impl FnOnce() -> T) -> T {
    sim.stepping_in_real_time(f)
}

#[test]
fn state_matches_the_controller_and_the_kinematic_model() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut robot = connect(&sim);
    assert_eq!(robot.controller_version().major, 5);
    assert_eq!(robot.period_s(), 0.002);
    let n0 = robot.state_count();
    wait_until("50 more states", || {
        robot.keep_alive().unwrap();
        robot.state_count() >= n0 + 50
    });
    let s = robot.state().unwrap();
    assert!(s.fault().is_none(), "{:?}", s.fault());
    assert_eq!(s.runtime_state, RuntimeState::Playing);
    assert!(s.program_ours);
    let q = sim.with(|c| c.q());
    for (a, b) in s.actual_q.iter().zip(&q) {
        assert!((a - b).abs() < 1e-12, "a robot at rest");
    }
    let fk = Arm::new(Model::Ur5e).fk(&s.actual_q);
    assert!(translation_error(&fk, &s.base_from_tcp) < 1e-12);
}

#[test]
fn the_wrench_on_the_tool_reaches_the_client_in_the_base_and_the_tool_frame() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut robot = connect(&sim);
    // Free space: no wrench.
    wait_until("a state", || {
        robot.keep_alive().unwrap();
        robot.state().is_some()
    });
    assert_eq!(robot.state().unwrap().tcp_force, [0.0; 6]);
    // A contact pushes the tool up (+z of the base) by 12.5 N, with a torque about x.
    let w = [0.0, 0.0, 12.5, 0.3, 0.0, 0.0];
    sim.with(|c| c.set_tcp_force(w));
    wait_until("the wrench in the state", || {
        robot.keep_alive().unwrap();
        robot.state().is_some_and(|s| s.tcp_force == w)
    });
    // In the tool's frame: the working pose's tool z points down, so the push is along -z
    // of the tool, whatever its rotation about z.
    let s = robot.state().unwrap();
    let tool = s.tcp_force_in_tool();
    let expected =
        s.base_from_tcp.rotation.inverse() * mocomp_geom::nalgebra::Vector3::new(0.0, 0.0, 12.5);
    for i in 0..3 {
        assert!(
            (tool[i] - expected[i]).abs() < 1e-12,
            "{tool:?} vs {expected:?}"
        );
    }
    let norm = (tool[0].powi(2) + tool[1].powi(2) + tool[2].powi(2)).sqrt();
    assert!((norm - 12.5).abs() < 1e-12);
    let torque = (tool[3].powi(2) + tool[4].powi(2) + tool[5].powi(2)).sqrt();
    assert!((torque - 0.3).abs() < 1e-12);
}

#[test]
fn zeroing_the_force_sensor_takes_its_present_reading_as_zero_and_a_cb3_has_none() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut robot = connect(&sim);
    // The sensor reads a bias (the coil's weight, a drift) with nothing touching the tool.
    let bias = [1.25, -0.5, -7.75, 0.05, 0.0, -0.02];
    sim.with(|c| c.set_tcp_force(bias));
    wait_until("the bias in the state", || {
        robot.keep_alive().unwrap();
        robot.state().is_some_and(|s| s.tcp_force == bias)
    });
    robot.zero_force_sensor().unwrap();
    wait_until("a zero reading", || {
        robot.keep_alive().unwrap();
        robot.state().is_some_and(|s| s.tcp_force == [0.0; 6])
    });
    // A contact from now on reads as itself.
    let push = [0.0, 0.0, 4.0, 0.0, 0.0, 0.0];
    sim.with(|c| c.set_tcp_force(std::array::from_fn(|i| bias[i] + push[i])));
    wait_until("the contact alone", || {
        robot.keep_alive().unwrap();
        robot
            .state()
            .is_some_and(|s| (0..6).all(|i| (s.tcp_force[i] - push[i]).abs() < 1e-12))
    });
    assert!(
        sim.with(|c| c
            .events()
            .0
            .iter()
            .any(|e| e.text.contains("sensor zeroed"))),
        "the controller logged the zeroing"
    );
    let cb3 = self::sim(Model::Ur5, SimClock::RealTime);
    let mut old = connect(&cb3);
    let e = old.zero_force_sensor().unwrap_err();
    assert!(e.to_string().contains("CB3 has none"), "{e}");
}

#[test]
fn digital_outputs_set_through_rtde_change_only_their_bit_and_inputs_reach_the_state() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut robot = connect(&sim);
    // The world drives standard input 2 and configurable input 9 (a stimulator's pulse).
    sim.with(|c| {
        c.set_digital_input(2, true);
        c.set_digital_input(9, true);
    });
    wait_until("the inputs in the state", || {
        robot.keep_alive().unwrap();
        robot
            .state()
            .is_some_and(|s| s.digital_inputs == (1 << 2) | (1 << 9))
    });
    robot.set_digital_output(7, true).unwrap();
    robot.set_digital_output(10, true).unwrap();
    wait_until("outputs 7 and 10 high", || {
        robot.keep_alive().unwrap();
        robot
            .state()
            .is_some_and(|s| s.digital_outputs == (1 << 7) | (1 << 10))
    });
    assert_eq!(sim.with(|c| c.io().digital_outputs()), (1 << 7) | (1 << 10));
    // Low again: the other output stays as it was.
    robot.set_digital_output(7, false).unwrap();
    wait_until("output 7 low, 10 still high", || {
        robot.keep_alive().unwrap();
        robot.state().is_some_and(|s| s.digital_outputs == 1 << 10)
    });
    // The tool's outputs are not RTDE's to set.
    let e = robot.set_digital_output(16, true).unwrap_err();
    assert!(e.to_string().contains("digital output 16"), "{e}");
}

#[test]
fn free_drive_follows_a_hand_while_the_client_talks_and_ends_when_it_falls_silent() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut robot = connect(&sim);
    wait_until("a state", || {
        robot.keep_alive().unwrap();
        robot.state().is_some()
    });
    let arm = Arm::new(Model::Ur5e);
    let p0 = arm.fk(&robot.state().unwrap().actual_q).translation.vector;
    robot.freedrive().unwrap();
    wait_until("free-drive", || {
        robot.keep_alive().unwrap();
        robot
            .state()
            .is_some_and(|s| s.program_mode == mocomp_ur::program::mode::FREEDRIVE)
    });
    // A hand pushes the coil down (−z) with 20 N: the arm yields while the client keeps talking.
    sim.with(|c| c.set_tcp_force([0.0, 0.0, -20.0, 0.0, 0.0, 0.0]));
    wait_until("the arm to yield 2 cm", || {
        robot.keep_alive().unwrap();
        robot
            .state()
            .is_some_and(|s| p0.z - arm.fk(&s.actual_q).translation.vector.z > 0.02)
    });
    // The client falls silent: the watchdog ends the program and free-drive with it.
    wait_until("the watchdog", || {
        sim.with(|c| c.runtime_state()) == RuntimeState::Stopped
    });
    let events = sim.with(|c| c.event_texts());
    assert!(
        events.iter().any(|e| e.contains("free-drive started")),
        "{events:?}"
    );
    assert!(events.iter().any(|e| e.contains("watchdog")), "{events:?}");
    wait_until("standstill", || {
        sim.with(|c| c.qd().iter().all(|v| *v == 0.0))
    });
}

#[test]
fn servo_streaming_tracks_a_trajectory_on_a_stepped_clock_deterministically() {
    fn run() -> (f64, Vec<[f64; 6]>) {
        let sim = sim(Model::Ur3e, SimClock::Stepped);
        let mut robot = pumped(&sim, || connect(&sim));
        let q0 = robot.state().unwrap().actual_q;
        let params = ServoParams {
            time_s: 0.002,
            lookahead_s: 0.05,
            gain: 1000.0,
        };
        let mut max_err: f64 = 0.0;
        let mut trace = Vec::new();
        for k in 0..1500 {
            // Lockstep: one command per controller cycle, one state per cycle.
            let t = k as f64 * 0.002;
            let mut q = q0;
            q[0] += 0.3 * (1.0 - (2.0 * t).cos());
            q[4] += 0.2 * (3.0 * t).sin();
            let n = sim.stats().inputs;
            robot.servo(&q, &params).unwrap();
            spin_until("the command at the simulator", || sim.stats().inputs > n);
            let before = robot.state_count();
            sim.step();
            spin_until("the state", || robot.state_count() > before);
            let s = robot.state().unwrap();
            // The servo lags a moving target by about lookahead × speed (≤ 0.05 × 0.6 rad/s).
            if k > 100 {
                max_err = max_err.max((s.actual_q[0] - q[0]).abs());
            }
            trace.push(s.actual_q);
        }
        assert_eq!(sim.with(|c| c.protective_stops()), 0);
        (max_err, trace)
    }
    let (e1, t1) = run();
    let (e2, t2) = run();
    assert!(e1 < 0.035 && e1 > 0.001, "tracking error {e1} rad");
    assert_eq!(e1, e2);
    assert_eq!(t1, t2, "bit-identical runs on the stepped clock");
}

#[test]
fn a_program_stopped_before_the_clients_first_feed_is_uploaded_again_twice_at_most() {
    // A busy PC can hold the client back between the upload and its first command for longer
    // than the program's watchdog allows: the program stops before it was ever fed, on a
    // healthy robot that has not moved. The simulator makes that race happen every time.
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut cfg = config_for(&sim);
    // Each lost program costs the client one wait for it to start: shorter than the default
    // so the test is quick, and still far beyond a start that takes a few cycles.
    cfg.program_start_timeout = Duration::from_secs(3);
    // A client that goes leaves its program running until the watchdog: 10 s here, so the
    // next client surely finds it running.
    cfg.watchdog_hz = 0.1;
    let count = |what: &str| {
        let (ev, _) = sim.with(|c| c.events());
        let n = ev.iter().filter(|e| e.text.contains(what)).count();
        (n, ev)
    };
    sim.with(|c| c.hold_back_first_feeds(2));
    let mut robot = UrRobot::connect(cfg.clone(), Arc::new(MonotonicClock::new())).unwrap();
    let s = robot.state().unwrap();
    assert_eq!(s.fault(), None, "{s:?}");
    // And it is fed: it moves when told.
    robot
        .servo(&s.actual_q, &ServoParams::for_period(0.002))
        .unwrap();
    let (n, ev) = count("first feed held back");
    assert_eq!(n, 2, "{ev:?}");
    let (n, ev) = count("mocomp control program started");
    assert_eq!(n, 3, "{ev:?}");
    drop(robot);
    // The next client finds that program still running, which would answer its wait for the
    // new one: it ends it first. A third lost program is then the caller's: refused, naming
    // what it waited for.
    sim.with(|c| c.hold_back_first_feeds(3));
    let Err(e) = UrRobot::connect(cfg, Arc::new(MonotonicClock::new())) else {
        panic!("connected with every program stopped before its first feed");
    };
    assert!(
        matches!(e, mocomp_ur::UrError::Timeout { .. })
            && e.to_string().contains("the control program to start"),
        "{e}"
    );
    let (n, ev) = count("the control program received EXIT");
    assert_eq!(n, 1, "{ev:?}");
    let (n, ev) = count("first feed held back");
    assert_eq!(n, 5, "{ev:?}");
}

#[test]
fn the_watchdog_stops_the_program_when_the_client_goes_silent() {
    let sim = sim(Model::Ur3e, SimClock::RealTime);
    let mut cfg = config_for(&sim);
    // 2 Hz: a test thread on a loaded machine is never silent for 500 ms by accident.
    cfg.watchdog_hz = 2.0;
    let mut robot = UrRobot::connect(cfg, Arc::new(MonotonicClock::new())).unwrap();
    let q = robot.state().unwrap().actual_q;
    let p = ServoParams::for_period(0.002);
    for _ in 0..50 {
        robot.servo(&q, &p).unwrap();
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(robot.state().unwrap().fault().is_none());
    // Silence: the program stops, and not before the watchdog's 500 ms.
    let silent = std::time::Instant::now();
    wait_until("the watchdog to stop the program", || {
        robot.state().unwrap().runtime_state == RuntimeState::Stopped
    });
    assert!(
        silent.elapsed() >= Duration::from_millis(480),
        "{:?}",
        silent.elapsed()
    );
    let s = robot.state().unwrap();
    assert_eq!(s.runtime_state, RuntimeState::Stopped);
    assert_eq!(s.fault(), Some(RobotFault::ProgramStopped));
    let (ev, _) = sim.with(|c| c.events());
    assert!(
        ev.iter().any(|e| e.text.contains("RTDE watchdog")),
        "{ev:?}"
    );
    // Commands are refused while the program is stopped, then it restarts on request.
    assert!(matches!(
        robot.servo(&q, &p),
        Err(RobotError::Fault(RobotFault::ProgramStopped))
    ));
    robot.restart_program().unwrap();
    assert!(robot.state().unwrap().fault().is_none());
}

#[test]
fn slow_work_between_commands_keeps_the_program_running_when_run_through_keep_alive_while() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut cfg = config_for(&sim);
    // 2 Hz as above; the work takes three watchdog periods.
    cfg.watchdog_hz = 2.0;
    let mut robot = UrRobot::connect(cfg, Arc::new(MonotonicClock::new())).unwrap();
    let answer = robot
        .keep_alive_while(|| {
            std::thread::sleep(Duration::from_millis(1500));
            42
        })
        .unwrap();
    assert_eq!(answer, 42);
    let s = robot.state().unwrap();
    assert_eq!(s.fault(), None);
    assert_eq!(s.runtime_state, RuntimeState::Playing);
    // The same work done without it stops the program (however long the machine takes to see
    // it: waited for, not slept).
    wait_until("the watchdog stops the unfed program", || {
        robot.state().unwrap().fault() == Some(RobotFault::ProgramStopped)
    });
}

#[test]
fn busy_work_keeps_the_program_running_under_a_real_time_caller_pinned_to_one_cpu() {
    // The loop's situation: the caller at SCHED_FIFO, pinned to one CPU; the work spins (no
    // blocking) for six watchdog periods. The worker must not inherit the caller's priority and
    // CPU, or the feeder could not preempt it. SCHED_FIFO needs root or an rtprio limit
    // (`/etc/security/limits.conf`); a user without either runs the same scenario with the
    // caller pinned at normal priority, which still checks that the work leaves the caller's
    // CPU and policy and that the watchdog is fed, though not against a real-time caller.
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let mut cfg = config_for(&sim);
    cfg.watchdog_hz = 20.0;
    let answer = std::thread::scope(|s| {
        s.spawn(|| {
            mocomp_rt::pin_to_cpu(0).expect("pinning the test's thread to CPU 0");
            if let Err(e) = mocomp_rt::set_fifo(40) {
                eprintln!("no SCHED_FIFO for this user ({e}): the caller is pinned only");
            }
            let mut robot = UrRobot::connect(cfg, Arc::new(MonotonicClock::new())).unwrap();
            let (answer, policy) = robot
                .keep_alive_while(|| {
                    let policy = mocomp_rt::current_policy().unwrap();
                    let start = std::time::Instant::now();
                    let mut spins = 0u64;
                    while start.elapsed() < Duration::from_millis(300) {
                        spins = std::hint::black_box(spins + 1);
                    }
                    (spins > 0, policy)
                })
                .unwrap();
            assert_eq!(policy, mocomp_rt::Policy::Normal, "the work left real time");
            // The controller's own account (the state read back may predate a stop).
            let stops: Vec<String> = sim.with(|c| {
                c.events()
                    .0
                    .iter()
                    .map(|e| e.text.clone())
                    .filter(|t| t.contains("stopped"))
                    .collect()
            });
            assert!(
                stops.is_empty(),
                "the watchdog starved behind the work: {stops:?}"
            );
            let s = robot.state().unwrap();
            assert_eq!(s.fault(), None);
            assert_eq!(s.runtime_state, RuntimeState::Playing);
            answer
        })
        .join()
        .unwrap()
    });
    assert!(answer);
}

#[test]
fn a_setpoint_jump_is_a_protective_stop_detected_at_once_and_recovered_via_the_dashboard() {
    let sim = sim(Model::Ur5e, SimClock::Stepped);
    let mut robot = pumped(&sim, || connect(&sim));
    let mut q = robot.state().unwrap().actual_q;
    let p = ServoParams::for_period(0.002);
    q[1] += 0.2; // 0.2 rad in one 2 ms cycle: 100 rad/s.
    let n = sim.stats().inputs;
    robot.servo(&q, &p).unwrap();
    wait_until("the command", || sim.stats().inputs > n);
    let before = robot.state_count();
    sim.step();
    wait_until("the next state", || robot.state_count() > before);
    // Detected in the very next state package.
    let s = robot.state().unwrap();
    assert_eq!(s.safety_mode, SafetyMode::ProtectiveStop);
    assert_eq!(s.fault(), Some(RobotFault::ProtectiveStop));
    assert!(matches!(
        robot.servo(&q, &p),
        Err(RobotError::Fault(RobotFault::ProtectiveStop))
    ));
    let (ev, _) = sim.with(|c| c.events());
    assert!(ev.iter().any(|e| e.text.contains("C204A3")), "{ev:?}");
    pumped(&sim, || robot.recover_protective_stop()).unwrap();
    let s = robot.state().unwrap();
    assert_eq!(s.safety_mode, SafetyMode::Normal);
    assert!(s.fault().is_none());
}

#[test]
fn movej_speedj_and_stopj_move_the_joints_as_commanded() {
    let sim = sim(Model::Ur10, SimClock::RealTime);
    let mut robot = connect(&sim);
    assert_eq!(robot.period_s(), 0.008, "CB3");
    let q0 = robot.state().unwrap().actual_q;
    let mut goal = q0;
    goal[0] += 0.3;
    goal[2] -= 0.2;
    let seq = robot.move_joints(&goal, 1.0, 4.0).unwrap();
    // A program that stopped under a wait is said with the controller's events, not left to
    // time out.
    let running = |sim: &Sim| {
        if sim.with(|c| c.runtime_state()) == RuntimeState::Stopped {
            panic!("the program stopped: {:?}", sim.with(|c| c.event_texts()));
        }
    };
    wait_until("the move", || {
        robot.keep_alive().unwrap();
        running(&sim);
        std::thread::sleep(Duration::from_millis(5));
        robot.state().unwrap().move_done_seq == seq
    });
    let q = robot.state().unwrap().actual_q;
    for j in 0..6 {
        assert!((q[j] - goal[j]).abs() < 1e-9, "joint {j}");
    }
    robot
        .speed_joints(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.5], 10.0)
        .unwrap();
    wait_until("speed", || {
        robot.keep_alive().unwrap();
        running(&sim);
        std::thread::sleep(Duration::from_millis(5));
        (robot.state().unwrap().actual_qd[5] - 0.5).abs() < 1e-9
    });
    robot.stop(5.0).unwrap();
    wait_until("standstill", || {
        robot.keep_alive().unwrap();
        std::thread::sleep(Duration::from_millis(5));
        let s = robot.state().unwrap();
        s.actual_qd.iter().all(|v| *v == 0.0) && s.program_mode == 1
    });
    assert!(robot.state().unwrap().fault().is_none());
}

#[test]
fn emergency_stop_and_connection_loss_are_detected() {
    let sim = sim(Model::Ur3e, SimClock::RealTime);
    let robot = connect(&sim);
    sim.with(|c| c.emergency_stop());
    wait_until("e-stop seen", || {
        robot.state().unwrap().fault() == Some(RobotFault::EmergencyStop)
    });
    drop(sim);
    wait_until("disconnect seen", || !robot.state().unwrap().connected);
    assert_eq!(
        robot.state().unwrap().fault(),
        Some(RobotFault::Disconnected)
    );
    assert!(robot.last_error().is_some());
    let clock = MonotonicClock::new();
    assert_eq!(
        robot.fault_at(clock.now_s() + 1e6, 0.01),
        Some(RobotFault::Disconnected)
    );
}

#[test]
fn protocol_1_controllers_are_handled() {
    let mut c = SimConfig::stepped_local(ControllerConfig::new(Model::Ur5));
    c.clock = SimClock::RealTime;
    c.max_protocol = 1;
    let sim = Sim::start(c).unwrap();
    let mut conn = RtdeConnection::connect(sim.addrs().rtde, Duration::from_secs(2)).unwrap();
    assert_eq!(conn.negotiate().unwrap(), 1);
    let mut robot = connect(&sim);
    wait_until("states", || {
        robot.keep_alive().unwrap();
        robot.state_count() > 10
    });
    assert!(robot.state().unwrap().fault().is_none());
}

#[test]
fn unknown_and_busy_variables_are_named() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let t = Duration::from_secs(2);
    let mut a = RtdeConnection::connect(sim.addrs().rtde, t).unwrap();
    a.negotiate().unwrap();
    let e = a
        .setup_outputs(500.0, &["timestamp", "actual_qq", "actual_q"])
        .unwrap_err();
    assert!(e.to_string().contains("actual_qq (NOT_FOUND)"), "{e}");
    a.setup_inputs(&["input_int_register_30", "input_double_register_30"])
        .unwrap();
    // The same connection may reuse its registers in another recipe (ur_rtde does).
    let r2 = a.setup_inputs(&["input_int_register_30"]).unwrap();
    assert_eq!(r2.id, 2, "input recipes numbered per connection");
    let mut b = RtdeConnection::connect(sim.addrs().rtde, t).unwrap();
    b.negotiate().unwrap();
    let e = b
        .setup_inputs(&["input_int_register_31", "input_double_register_30"])
        .unwrap_err();
    assert!(e.to_string().contains("input_double_register_30"), "{e}");
    assert!(e.to_string().contains("IN_USE"), "{e}");
    a.shutdown();
    drop(a);
    wait_until("release on disconnect", || sim.rtde_connections() == 1);
    b.setup_inputs(&["input_double_register_30"]).unwrap();
}

#[test]
fn the_client_powers_on_and_reconnects_on_request() {
    // Standard ports on its own loopback address, so a restarted controller is at the same place.
    let host: std::net::IpAddr = "127.0.79.2".parse().unwrap();
    let mut ctrl = ControllerConfig::new(Model::Ur3e);
    ctrl.powered = false;
    let sim = Sim::start(SimConfig::new(ctrl.clone(), host)).unwrap();
    let mut cfg = UrConfig::new(host);
    // Powered off: refused, naming the mode …
    let e = UrRobot::connect(cfg.clone(), Arc::new(MonotonicClock::new())).unwrap_err();
    assert!(e.to_string().contains("POWER_OFF"), "{e}");
    // … unless asked to power on and release the brakes.
    cfg.power_on = true;
    let mut robot = UrRobot::connect(cfg, Arc::new(MonotonicClock::new())).unwrap();
    assert!(robot.state().unwrap().fault().is_none());
    drop(sim);
    wait_until("the loss seen", || {
        robot.state().unwrap().fault() == Some(RobotFault::Disconnected)
    });
    let _sim = Sim::start(SimConfig::new(ControllerConfig::new(Model::Ur3e), host)).unwrap();
    robot.reconnect().unwrap();
    assert!(robot.state().unwrap().fault().is_none());
}

#[test]
fn a_state_reader_that_panics_is_a_named_lost_connection() {
    let sim = sim(Model::Ur5e, SimClock::RealTime);
    let clock = mocomp_testkit::mem::PanicsOnce::on_reading(200);
    let mut robot = UrRobot::connect(config_for(&sim), Arc::new(clock)).unwrap();
    wait_until("the reader's failure seen as a lost connection", || {
        robot.keep_alive().ok();
        robot.state().is_some_and(|s| !s.connected)
    });
    assert_eq!(
        robot.state().unwrap().fault(),
        Some(RobotFault::Disconnected)
    );
    let e = robot.last_error().unwrap_or_default();
    assert!(
        e.contains("ur-state panicked") && e.contains("injected fault on reading 200"),
        "{e}"
    );
}
