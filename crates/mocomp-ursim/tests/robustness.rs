#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
//! Malformed input to the simulator (and a malformed controller to the client): nothing panics,
//! nothing hangs, the simulator keeps serving well-behaved clients.

use mocomp_geom::MonotonicClock;
use mocomp_kin::Model;
use mocomp_testkit::{SplitMix64, wait_until};
use mocomp_ur::codec::{Direction, Recipe, Request, encode_request};
use mocomp_ur::connection::RtdeConnection;
use mocomp_ur::types::Value;
use mocomp_ur::{Robot, UrError, UrRobot};
use mocomp_ursim::{ControllerConfig, Sim, SimClock, SimConfig};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::time::Duration;

fn blast(addr: SocketAddr, bytes: &[u8]) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(5))).unwrap();
    s.write_all(bytes).ok();
    let mut sink = [0u8; 4096];
    let _ = s.read(&mut sink);
}

fn frame(r: &Request<'_>, version: u16) -> Vec<u8> {
    let mut b = Vec::new();
    encode_request(r, version, &mut b).unwrap();
    b
}

#[test]
fn garbage_on_every_port_leaves_the_simulator_serving() {
    let mut c = SimConfig::stepped_local(ControllerConfig::new(Model::Ur5e));
    c.clock = SimClock::RealTime;
    let sim = Sim::start(c).unwrap();
    let a = sim.addrs();
    let mut rng = SplitMix64(0x6761_7262);
    // Arbitrary bytes.
    for _ in 0..20 {
        let n = (rng.next_u64() % 3000) as usize;
        let bytes: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
        for addr in [a.rtde, a.dashboard, a.realtime, a.primary, a.secondary] {
            blast(addr, &bytes);
        }
    }
    // Well-framed but wrong: truncated payloads, wrong sizes, unknown types, data for unknown
    // recipes, data of the wrong size, a size below the header.
    let mut wrong = Vec::new();
    wrong.extend_from_slice(&frame(&Request::ProtocolVersion(2), 2));
    wrong.extend_from_slice(&[0, 4, b'V', 0]); // V with 1 byte
    wrong.extend_from_slice(&[0, 5, b'v', 1, 2]); // v with a payload
    wrong.extend_from_slice(&[0, 4, b'Z', 9]); // unknown type
    wrong.extend_from_slice(&[0, 6, b'U', 42, 1, 2]); // unknown input recipe
    wrong.extend_from_slice(&frame(
        &Request::SetupInputs {
            names: vec!["input_int_register_40".into()],
        },
        2,
    ));
    wrong.extend_from_slice(&[0, 6, b'U', 1, 1, 2]); // recipe 1 needs 4 bytes
    wrong.extend_from_slice(&[0, 5, b'O', 0x40, 0x5f]); // O shorter than its frequency
    wrong.extend_from_slice(&[0, 4, b'O', 0xff]);
    wrong.extend_from_slice(&[0, 4, b'I', 0xc3]); // not UTF-8
    wrong.extend_from_slice(&frame(&Request::Start, 2)); // START without outputs: refused
    wrong.extend_from_slice(&[0, 1, b'S']); // size below the header: connection closed
    blast(a.rtde, &wrong);
    blast(a.dashboard, &[b'x'; 10_000]);
    blast(a.dashboard, b"power on\xff\xfe\nrobotmode\n\n\n");
    blast(
        a.realtime,
        b"def foo():\n  movej([0,0,0,0,0,0])\nend\nstopj(2)\n\xff\xff\n",
    );
    wait_until("the bad packages counted", || sim.stats().bad_packages >= 8);
    // The simulator still serves a well-behaved client, and nothing moved the arm.
    // Its watchdog at 2 Hz: the test's ordinary thread keeps the program alive, and a loaded
    // machine may not schedule it for the default's 50 ms (a stopped program is a fault).
    let mut cfg = sim.ur_config();
    cfg.watchdog_hz = 2.0;
    let mut robot = UrRobot::connect(cfg, Arc::new(MonotonicClock::new())).unwrap();
    let n = robot.state_count();
    wait_until("states", || {
        robot.keep_alive().unwrap();
        robot.state_count() > n + 10
    });
    assert!(robot.state().unwrap().fault().is_none());
    assert_eq!(sim.with(|c| c.protective_stops()), 0);
    let (events, _) = sim.with(|c| c.events());
    assert!(
        events.iter().any(|e| e.text.contains("not run")),
        "the foreign program is refused"
    );
}

/// A fake controller that answers every request with `reply`.
fn fake_controller(reply: Vec<u8>) -> SocketAddr {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap();
    std::thread::spawn(move || {
        if let Ok((mut s, _)) = l.accept() {
            let mut buf = [0u8; 1024];
            while let Ok(n) = s.read(&mut buf) {
                if n == 0 || s.write_all(&reply).is_err() {
                    break;
                }
            }
        }
    });
    addr
}

#[test]
fn a_malformed_controller_gives_named_errors_not_panics() {
    let t = Duration::from_millis(300);
    // A version reply of the wrong size.
    let mut c = RtdeConnection::connect(fake_controller(vec![0, 5, b'V', 1, 1]), t).unwrap();
    let e = c.negotiate().unwrap_err();
    assert!(e.to_string().contains("malformed RTDE package 'V'"), "{e}");
    // A size field below the header.
    let mut c = RtdeConnection::connect(fake_controller(vec![0, 2, b'V']), t).unwrap();
    let e = c.negotiate().unwrap_err();
    assert!(e.to_string().contains("below the 3-byte header"), "{e}");
    // Silence: a timeout, not a hang.
    let mut c = RtdeConnection::connect(fake_controller(Vec::new()), t).unwrap();
    assert!(matches!(c.negotiate(), Err(UrError::Timeout { .. })));
    // Arbitrary bytes, seeded.
    let mut rng = SplitMix64(7);
    for _ in 0..30 {
        let n = (rng.next_u64() % 200) as usize;
        let bytes: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
        let quick = Duration::from_millis(30);
        let mut c = RtdeConnection::connect(fake_controller(bytes), quick).unwrap();
        let _ = c.negotiate().and_then(|_| c.controller_version());
    }
    // A data package of the wrong size for the recipe.
    let recipe = Recipe::from_table(1, &["timestamp", "actual_q"], Direction::Output).unwrap();
    let mut c =
        RtdeConnection::connect(fake_controller(vec![0, 8, b'U', 1, 0, 0, 0, 0]), t).unwrap();
    c.send_text("hello", "test", 3).unwrap();
    let mut v: Vec<Value> = Vec::new();
    let e = c.receive(&recipe, &mut v, false).unwrap_err();
    assert!(
        e.to_string().contains("has 5 bytes, the recipe needs 56"),
        "{e}"
    );
}
