//! Client and server on loopback: poses through the PoseSource, queries, TDATA streams, many
//! clients, a slow client, and the faults: a server restart mid-stream, garbage, a truncated
//! message, a bad CRC, zero and backwards timestamps, invalid status, non-rigid transforms.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_geom::{Clock, PoseSource, rotation_error, translation_error};
use mocomp_igtl::client::{Client, ClientConfig, MonotonicClock, TimestampMode};
use mocomp_igtl::message::{Body, MetaEntry, TDataElement, transform_floats};
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{DeviceName, Message, Timestamp, encode};
use mocomp_testkit::wait_until;
use std::io::Write;
use std::net::TcpListener;
use std::sync::Arc;
use std::time::Duration;

fn pose(k: f64) -> Isometry3<f64> {
    Isometry3::new(
        Vector3::new(0.1 + 0.001 * k, -0.2, 0.9),
        Vector3::new(0.2, -0.1, 0.05 * k),
    )
}

fn client(addr: &str, device: &str) -> Client {
    let mut c = ClientConfig::new(addr);
    c.device = Some(device.to_string());
    c.keep_messages = 100_000;
    Client::start(c, Arc::new(MonotonicClock::new()))
}

fn server() -> Server {
    Server::bind("127.0.0.1:0", ServerConfig::default()).unwrap()
}

#[test]
fn poses_flow_from_server_to_pose_source() {
    let s = server();
    let c = client(&s.local_addr().to_string(), "HeadToTracker");
    let mut src = c.pose_source();
    wait_until("connection", || s.client_count() == 1);
    assert!(src.latest().is_none());
    for k in 0..50 {
        s.send(
            &Message::transform("HeadToTracker", &pose(f64::from(k)), Timestamp::now()).unwrap(),
        );
        s.send(&Message::transform("StylusToTracker", &pose(-1.0), Timestamp::now()).unwrap());
    }
    // The reader counts a message's pose before the message itself, and the other device's
    // last transform comes after the 50th pose: wait for every one of them.
    wait_until("50 poses among 100 transforms", || {
        let n = c.counters();
        n.poses == 50 && n.transforms == 100
    });
    let sample = src.latest().unwrap();
    assert!(sample.valid);
    assert!(
        translation_error(&sample.tracker_from_marker, &pose(49.0)) < 1e-6,
        "mm → m at the edge, f32 precision"
    );
    assert!(rotation_error(&sample.tracker_from_marker, &pose(49.0)) < 1e-6);
    assert!(src.latest().is_none(), "nothing new");
    let n = c.counters();
    assert_eq!((n.transforms, n.crc_errors, n.zero_timestamps), (100, 0, 0));
}

#[test]
fn queries_are_answered() {
    let s = server();
    let c = client(&s.local_addr().to_string(), "HeadToTracker");
    wait_until("connection", || c.is_connected() && s.client_count() == 1);
    s.send(&Message::transform("HeadToTracker", &pose(7.0), Timestamp::now()).unwrap());
    wait_until("first transform", || c.counters().transforms == 1);
    let rx = c.take_messages().unwrap();
    while rx.try_recv().is_ok() {}
    for t in ["GET_TRANS", "GET_TRANSFOR"] {
        c.send(&Message::new(t, "HeadToTracker", Body::Query(vec![])).unwrap())
            .unwrap();
        let r = rx.recv_timeout(mocomp_testkit::HUNG).unwrap();
        assert_eq!(r.message.type_name, "TRANSFORM", "{t}");
        assert_eq!(
            r.message.body,
            Body::Transform(transform_floats(&pose(7.0)))
        );
    }
    c.send(&Message::new("GET_TRANS", "NoSuchTool", Body::Query(vec![])).unwrap())
        .unwrap();
    let r = rx.recv_timeout(mocomp_testkit::HUNG).unwrap();
    assert!(
        matches!(&r.message.body, Body::Status(st) if st.code == 4),
        "{:?}",
        r.message.body
    );
    c.send(&Message::new("GET_IMAGE", "US", Body::Query(vec![])).unwrap())
        .unwrap();
    let r = rx.recv_timeout(mocomp_testkit::HUNG).unwrap();
    assert!(matches!(&r.message.body, Body::Status(st) if st.code == 12));
    assert_eq!(s.counters().queries, 4);
}

#[test]
fn tdata_streams_only_to_clients_that_ask() {
    let s = server();
    let mut cfg = ClientConfig::new(&s.local_addr().to_string());
    cfg.device = Some("HeadToTracker".into());
    cfg.start_tdata = Some(0);
    let asking = Client::start(cfg, Arc::new(MonotonicClock::new()));
    let quiet = client(&s.local_addr().to_string(), "HeadToTracker");
    wait_until("two clients", || s.client_count() == 2);
    wait_until("RTS_TDATA", || asking.counters().queries == 1);
    let tools = vec![
        TDataElement {
            name: DeviceName::new("HeadToTracker").unwrap(),
            kind: 2,
            matrix: transform_floats(&pose(3.0)),
        },
        TDataElement {
            name: DeviceName::new("CoilToTracker").unwrap(),
            kind: 2,
            matrix: transform_floats(&pose(4.0)),
        },
    ];
    for _ in 0..10 {
        s.send(&Message::new("TDATA", "Tracker", Body::TData(tools.clone())).unwrap());
    }
    wait_until("TDATA", || asking.counters().tdata == 10);
    let sample = asking.pose_source().latest().unwrap();
    assert!(
        translation_error(&sample.tracker_from_marker, &pose(3.0)) < 1e-6,
        "the tool named like the device"
    );
    // A TRANSFORM sent to everyone after the TDATA: once the quiet client has it, anything sent
    // before it on that connection has arrived too (one ordered stream), so no TDATA was sent.
    s.send(&Message::transform("HeadToTracker", &pose(5.0), Timestamp::now()).unwrap());
    wait_until("the quiet client's TRANSFORM", || {
        quiet.counters().poses == 1
    });
    assert_eq!(quiet.counters().tdata, 0);
}

#[test]
fn many_clients_get_everything_and_a_slow_one_is_dropped() {
    // Small queues and 64 KB messages: a client that stops reading fills the kernel's socket
    // buffers (megabytes), then its queue, and is dropped; the others are never held up.
    let s = Server::bind(
        "127.0.0.1:0",
        ServerConfig {
            queue: 16,
            ..ServerConfig::default()
        },
    )
    .unwrap();
    let addr = s.local_addr().to_string();
    let clients: Vec<Client> = (0..4).map(|_| client(&addr, "HeadToTracker")).collect();
    let _slow = std::net::TcpStream::connect(&addr).unwrap();
    wait_until("five clients", || s.client_count() == 5);
    let m = Message::new("IMAGE", "US", Body::Unknown { size: 64 * 1024 }).unwrap();
    let n = 600u64;
    for i in 1..=n {
        s.send(&m);
        // Keep the good clients within half a queue: only the silent one can fall behind.
        wait_until("good clients keeping up", || {
            clients.iter().all(|c| c.counters().unknown + 8 >= i)
        });
    }
    for c in &clients {
        wait_until("all messages", || c.counters().unknown == n);
    }
    assert_eq!(s.counters().dropped_slow, 1, "{:?}", s.counters());
    assert_eq!(s.client_count(), 4);
}

/// A raw server that plays `script` to each connection in turn (one entry per connection).
fn scripted(script: Vec<Vec<u8>>) -> (String, std::thread::JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = l.local_addr().unwrap().to_string();
    let h = std::thread::spawn(move || {
        for bytes in script {
            let (mut s, _) = l.accept().unwrap();
            s.write_all(&bytes).unwrap();
            std::thread::sleep(Duration::from_millis(50));
        }
        // Keep the last connection's peer closed; accept no more.
    });
    (addr, h)
}

fn tf(k: f64, ts: Timestamp) -> Vec<u8> {
    encode(&Message::transform("HeadToTracker", &pose(k), ts).unwrap())
}

#[test]
fn garbage_truncation_and_bad_crc_are_counted_and_survived() {
    let mut bad_crc = tf(1.0, Timestamp::now());
    bad_crc[70] ^= 0x10;
    let good = tf(2.0, Timestamp::now());
    let mut garbage = vec![0x47u8, 0x45, 0x54, 0x20]; // "GET " — an HTTP client, say
    garbage.extend((0..200u32).map(|i| (i * 37 % 251) as u8));
    let truncated = good[..80].to_vec();
    let (addr, h) = scripted(vec![
        [bad_crc, good.clone()].concat(),
        garbage,
        truncated,
        good.clone(),
    ]);
    let c = client(&addr, "HeadToTracker");
    wait_until("four connections", || {
        c.counters().connections >= 4 && c.counters().transforms >= 2
    });
    let n = c.counters();
    assert_eq!(n.crc_errors, 1, "{n:?}");
    assert_eq!(n.fatal_errors, 1, "garbage ends the connection: {n:?}");
    assert!(n.truncated >= 1, "{n:?}");
    assert_eq!(n.transforms, 2, "{n:?}");
    h.join().unwrap();
    assert!(c.last_error().is_some());
}

#[test]
fn zero_and_backwards_timestamps_are_flagged() {
    let t0 = Timestamp::now();
    let later = Timestamp::from_secs_f64(t0.to_secs_f64() + 1.0);
    let bytes = [tf(1.0, Timestamp::NONE), tf(2.0, later), tf(3.0, t0)].concat();
    let (addr, _h) = scripted(vec![bytes]);
    let c = client(&addr, "HeadToTracker");
    let mut src = c.pose_source();
    wait_until("three poses", || c.counters().poses == 3);
    let n = c.counters();
    assert_eq!((n.zero_timestamps, n.backwards_timestamps), (1, 1));
    let s = src.latest().unwrap();
    assert!(s.acquired_s.is_finite() && s.acquired_s >= 0.0);
}

#[test]
fn status_metadata_and_non_rigid_transforms_make_samples_invalid() {
    let missing = Message::transform("HeadToTracker", &pose(1.0), Timestamp::now())
        .unwrap()
        .with_metadata(vec![MetaEntry::text("TransformStatus", "MISSING")]);
    let ok = Message::transform("HeadToTracker", &pose(2.0), Timestamp::now())
        .unwrap()
        .with_metadata(vec![MetaEntry::text("TransformStatus", "OK")]);
    let mut skewed = Message::transform("HeadToTracker", &pose(3.0), Timestamp::now()).unwrap();
    if let Body::Transform(f) = &mut skewed.body {
        f[0] *= 1.5; // scaled: not a rotation
    }
    let (addr, _h) = scripted(vec![
        [encode(&ok), encode(&missing), encode(&skewed)].concat(),
    ]);
    let c = client(&addr, "HeadToTracker");
    let rx_src = c.pose_source();
    let mut src = rx_src;
    wait_until("three poses", || c.counters().poses == 3);
    let s = src.latest().unwrap();
    assert!(!s.valid);
    assert!(
        translation_error(&s.tracker_from_marker, &pose(2.0)) < 1e-6,
        "the last valid pose is carried"
    );
    let n = c.counters();
    assert_eq!((n.invalid_poses, n.non_rigid), (2, 1), "{n:?}");
}

#[test]
fn a_server_restart_mid_stream_is_survived() {
    let s = server();
    let addr = s.local_addr().to_string();
    let c = client(&addr, "HeadToTracker");
    wait_until("connection", || s.client_count() == 1);
    for k in 0..10 {
        s.send(
            &Message::transform("HeadToTracker", &pose(f64::from(k)), Timestamp::now()).unwrap(),
        );
    }
    wait_until("10 poses", || c.counters().poses == 10);
    s.stop();
    wait_until("disconnect", || !c.is_connected());
    let s2 = Server::bind(&addr, ServerConfig::default()).unwrap();
    wait_until("reconnect", || s2.client_count() == 1);
    for k in 10..20 {
        s2.send(
            &Message::transform("HeadToTracker", &pose(f64::from(k)), Timestamp::now()).unwrap(),
        );
    }
    wait_until("20 poses", || c.counters().poses == 20);
    let n = c.counters();
    assert_eq!(n.connections, 2);
    assert!(n.disconnects >= 1);
    let mut src = c.pose_source();
    assert!(translation_error(&src.latest().unwrap().tracker_from_marker, &pose(19.0)) < 1e-6);
}

#[test]
fn the_client_backs_off_while_nothing_listens() {
    // An address of this test's own, where nothing listens.
    let start = std::time::Instant::now();
    let c = client("127.0.89.1:18944", "HeadToTracker");
    wait_until("four refused connections", || {
        c.counters().connect_failures >= 4
    });
    // Waits of 50, 100, 200, … ms (doubling up to 2 s) between them: n failures take at least
    // the first n − 1 waits. A busy machine makes them longer, never shorter, so the count read
    // and the time taken after it must always fit; a client that did not back off would fail
    // hundreds of times in the span.
    let failures = c.counters().connect_failures;
    let elapsed = start.elapsed();
    let least: Duration = (0..failures.saturating_sub(1))
        .map(|i| Duration::from_millis(50 << i.min(10)).min(Duration::from_secs(2)))
        .sum();
    assert!(failures >= 4, "{failures}");
    assert!(
        elapsed >= least,
        "{failures} failures in {elapsed:?}, backing off would take {least:?}"
    );
}

/// Sends poses stamped `latency` before their sending time and returns the sample age the client
/// reports for the last one (receive-side clock minus the acquisition time it inferred).
fn observed_age(mode: TimestampMode, fixed_latency_s: f64, latency: f64) -> f64 {
    let s = server();
    let mut cfg = ClientConfig::new(&s.local_addr().to_string());
    cfg.device = Some("HeadToTracker".into());
    cfg.timestamps = mode;
    cfg.fixed_latency_s = fixed_latency_s;
    let clock = Arc::new(MonotonicClock::new());
    let c = Client::start(cfg, clock.clone());
    let mut src = c.pose_source();
    wait_until("connection", || s.client_count() == 1);
    for k in 0..20 {
        let ts = Timestamp::from_secs_f64(Timestamp::now().to_secs_f64() - latency);
        s.send(&Message::transform("HeadToTracker", &pose(f64::from(k)), ts).unwrap());
        std::thread::sleep(Duration::from_millis(2));
    }
    wait_until("20 poses", || c.counters().poses == 20);
    let sample = src.latest().unwrap();
    let received = clock.now_s();
    received - sample.acquired_s
}

#[test]
fn timestamps_synchronized_see_the_senders_latency_estimated_needs_it_given() {
    let latency = 0.040;
    // Same host: the 40 ms from acquisition to sending is seen (plus loopback and polling).
    let sync = observed_age(TimestampMode::Synchronized, 0.0, latency);
    assert!(
        (latency..latency + 0.030).contains(&sync),
        "synchronized: {sync}"
    );
    // Unsynchronised clocks: the minimum-delay offset absorbs the constant latency …
    let est = observed_age(TimestampMode::Estimated, 0.0, latency);
    assert!(est < 0.030, "estimated, no fixed latency: {est}");
    // … unless it is configured.
    let given = observed_age(TimestampMode::Estimated, latency, latency);
    assert!(
        (latency..latency + 0.030).contains(&given),
        "estimated with the fixed latency given: {given}"
    );
}

#[test]
fn flush_waits_until_every_client_has_been_written_to() {
    let s = server();
    let c = client(&s.local_addr().to_string(), "HeadToTracker");
    wait_until("connection", || s.client_count() == 1);
    for k in 0..500 {
        s.send(
            &Message::transform("HeadToTracker", &pose(f64::from(k)), Timestamp::now()).unwrap(),
        );
    }
    assert!(s.flush(Duration::from_secs(10)), "{:?}", s.counters());
    // Written means in the socket: the client gets all of it even once the server is gone.
    s.stop();
    wait_until("500 poses", || c.counters().poses == 500);
}

#[test]
fn a_reader_that_panics_is_named_counted_and_reconnects() {
    let s = server();
    let mut cfg = ClientConfig::new(&s.local_addr().to_string());
    cfg.device = Some("HeadToTracker".into());
    let clock = mocomp_testkit::mem::PanicsOnce::on_reading(3);
    let c = Client::start(cfg, Arc::new(clock));
    let mut src = c.pose_source();
    wait_until("connection", || s.client_count() == 1);
    // Send until 10 poses arrived: the third message's reading panics, the client drops that
    // connection and makes it again, and what is sent after arrives.
    let mut sent = 0;
    wait_until("10 poses after the reader's failure", || {
        s.send(&Message::transform("HeadToTracker", &pose(sent as f64), Timestamp::now()).unwrap());
        sent += 1;
        std::thread::sleep(Duration::from_millis(2));
        c.counters().poses >= 10
    });
    let n = c.counters();
    assert_eq!(n.reader_failures, 1, "{n:?}");
    assert_eq!(n.connections, 2, "{n:?}");
    assert_eq!(src.failures(), 1, "the loop sees it");
    let e = c.last_error().unwrap_or_default();
    assert!(
        e.contains("igtl-client panicked") && e.contains("injected fault on reading 3"),
        "{e}"
    );
    assert!(src.latest().unwrap().valid);
}
