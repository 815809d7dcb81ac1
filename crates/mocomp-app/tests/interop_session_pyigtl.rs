//! The session's OpenIGTLink side against pyigtl 0.3.4 (an independent Python implementation)
//! as the server a navigation system or TMS software would run: its STRING `pulse` reaches the
//! loop as a pulse with the sender's timestamp and the output it says (any other text does not),
//! and the gate the session publishes reads back in pyigtl as the STRING `open` / `shut: why`.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_app::frontend::Note;
use mocomp_app::live::session::{SessionLog, SessionSetup, forward_pulses};
use mocomp_igtl::client::{Client, ClientConfig, MonotonicClock};
use mocomp_session::{GateEvent, SessionParams, Shut};
use mocomp_testkit::{PythonPeer, wait_until};
use serde_json::json;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::sync_channel;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

#[test]
fn pulses_from_pyigtl_reach_the_loop_and_the_gate_reads_back_in_pyigtl() {
    let mut py = PythonPeer::start("pyigtl_peer.py", "pyigtl", "0.3.4");
    let port = py.request(&json!({"op": "server", "port": 0}))["port"]
        .as_u64()
        .unwrap();
    let mut cfg = ClientConfig::new(&format!("127.0.0.1:{port}"));
    cfg.keep_messages = 64;
    let client = Arc::new(Client::start(cfg, Arc::new(MonotonicClock::new())));
    wait_until("pyigtl sees our client", || {
        py.request(&json!({"op": "connected"}))["connected"] == true
    });

    // Pulses: the forwarding thread, as `mocomp run` starts it.
    let (tx, rx) = sync_channel(8);
    let stop = Arc::new(AtomicBool::new(false));
    let messages = client.take_messages().unwrap();
    let forwarding = {
        let stop = Arc::clone(&stop);
        std::thread::spawn(move || forward_pulses(&messages, &tx, &stop))
    };
    let send = |py: &mut PythonPeer, device: &str, text: &str| {
        py.request(
            &json!({"op": "send", "kind": "string", "device": device, "string": text,
            "timestamp": 1_700_000_000.0, "header_version": 2}),
        );
    };
    send(&mut py, "Stimulator", "pulse");
    let a = rx
        .recv_timeout(Duration::from_secs(10))
        .expect("the pulse reached the loop's channel");
    // pyigtl's header timestamp is the stimulator's own time of the pulse.
    let own = a.stimulator_unix_s.expect("the sender's timestamp");
    assert!((own - 1_700_000_000.0).abs() < 1e-6, "{a:?}");
    assert_eq!(a.output_pct, None);
    // Other text is not a pulse; the text's case and spaces do not matter; the output said is
    // kept.
    send(&mut py, "Note", "hello");
    send(&mut py, "Stimulator", "pulse output=abc");
    send(&mut py, "Stimulator", " PULSE output=65\n");
    let a = rx
        .recv_timeout(Duration::from_secs(10))
        .expect("the second pulse");
    assert_eq!(a.output_pct, Some(65.0));
    assert!(
        rx.recv_timeout(Duration::from_millis(300)).is_err(),
        "one pulse each"
    );

    // The gate, published on the same connection.
    let publisher = Arc::new(OnceLock::new());
    publisher.set(Arc::clone(&client)).ok();
    let setup = SessionSetup {
        targets: vec![("hot".into(), mocomp_geom::nalgebra::Isometry3::identity())],
        start: Some(0),
        params: SessionParams::default(),
        pulse_log: None,
        igtl_device: Some("MocompGate".into()),
        marker: None,
        recorder: mocomp_session::Recorder {
            utc_minus_loop_s: None,
            head_from_image: mocomp_geom::nalgebra::Isometry3::identity(),
            head: mocomp_control::HeadModel::adult(),
            output_pct: None,
        },
        dose: None,
    };
    let mut log = SessionLog::open(&setup, publisher).unwrap();
    let wait = |py: &mut PythonPeer| {
        let m = py.request(&json!({"op": "wait", "device": "MocompGate", "timeout": 60}));
        assert_eq!(m["found"], true, "{m}");
        assert_eq!(m["type"], "StringMessage", "{m}");
        m["string"].as_str().unwrap().to_string()
    };
    assert_eq!(
        log.take(&Note::Gate(1.0, GateEvent::Opened, Some(0))),
        "gate open on hot"
    );
    assert_eq!(wait(&mut py), "open");
    log.take(&Note::Gate(
        2.0,
        GateEvent::Shut(Shut::PositionError(0.003)),
        Some(0),
    ));
    assert_eq!(wait(&mut py), "shut: position error 3.00 mm");
    assert_eq!(log.report.gate_openings, 1);

    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    forwarding.join().unwrap();
}
