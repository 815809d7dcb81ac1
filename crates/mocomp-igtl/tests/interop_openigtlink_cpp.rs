//! Interop with the C++ OpenIGTLink library 1.11 from Debian (`libopenigtlink-dev`,
//! `openigtlink-examples`): its example `TrackerServer` streams to our client, and our server
//! feeds its example `ReceiveClient`. The examples ship as sources; this test builds them with g++.
//!
//! What this peer checks: header version 1, CRC-64 (it verifies every body and prints only what
//! passes, and drops a bad one while staying in step), TRANSFORM, POSITION, STATUS and TDATA
//! layouts, and the timestamp format. It does not know header version 2 (pyigtl covers that).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::PoseSource;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_igtl::client::{Client, ClientConfig, MonotonicClock};
use mocomp_igtl::message::{Body, Status, TDataElement, transform_floats};
use mocomp_igtl::name::Name;
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{DeviceName, Message, Timestamp, encode};
use mocomp_testkit::{listening_port, wait_until};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, OnceLock};
use std::time::{Duration, Instant};

const EXAMPLES: &str = "/usr/share/doc/openigtlink-examples/examples";
const INSTALL: &str = "install them with `apt-get install libopenigtlink-dev openigtlink-examples g++` (scripts/test.sh does)";

/// Builds `Tracker/TrackerServer` and `Receiver/ReceiveClient` once per test run.
fn peer(name: &str) -> PathBuf {
    static BUILT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let dir = BUILT.get_or_init(|| {
        let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("openigtlink-cpp");
        std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
        for (src, out) in [
            ("Tracker/TrackerServer.cxx", "TrackerServer"),
            ("Receiver/ReceiveClient.cxx", "ReceiveClient"),
        ] {
            let source = PathBuf::from(EXAMPLES).join(src);
            if !source.exists() {
                return Err(format!("{} is missing", source.display()));
            }
            let status = Command::new("g++")
                .args(["-O1", "-w", "-o"])
                .arg(dir.join(out))
                .arg(&source)
                .args(["-I/usr/include/openigtlink", "-lOpenIGTLink"])
                .status()
                .map_err(|e| format!("cannot run g++: {e}"))?;
            if !status.success() {
                return Err(format!("g++ failed to build {src} against libOpenIGTLink"));
            }
        }
        Ok(dir)
    });
    match dir {
        Ok(d) => d.join(name),
        Err(e) => panic!("interop peer OpenIGTLink C++ 1.11 missing: {e}; {INSTALL}"),
    }
}

struct Killed(Child);
impl Drop for Killed {
    fn drop(&mut self) {
        self.0.kill().ok();
        self.0.wait().ok();
    }
}

#[test]
fn our_server_feeds_the_cpp_receive_client() {
    let exe = peer("ReceiveClient");
    let server = Server::bind(
        "127.0.0.1:0",
        ServerConfig {
            push_tdata: true,
            ..ServerConfig::default()
        },
    )
    .unwrap();
    let child = Command::new(&exe)
        .args(["127.0.0.1", &server.local_addr().port().to_string()])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut child = Killed(child);
    wait_until("ReceiveClient connects", || server.client_count() == 1);
    let p = Isometry3::new(
        Vector3::new(0.011, 0.022, 0.033),
        Vector3::new(0.0, 0.0, 0.5),
    );
    server.send(
        &Message::transform(
            "HeadToTracker",
            &p,
            Timestamp::from_secs_f64(1_700_000_000.5),
        )
        .unwrap(),
    );
    // A TRANSFORM whose body we corrupt after encoding: the C++ library must drop it.
    let corrupted = Isometry3::translation(0.555, 0.555, 0.555);
    let far = Isometry3::translation(0.777, 0.777, 0.777);
    let mut bad = encode(&Message::transform("Corrupted", &corrupted, Timestamp::NONE).unwrap());
    bad[60] ^= 0x04;
    server.send_bytes(
        mocomp_igtl::TypeName::new("TRANSFORM").unwrap(),
        DeviceName::new("Corrupted").unwrap(),
        Arc::new(bad),
    );
    server.send(
        &Message::new(
            "POSITION",
            "Pos",
            Body::Position {
                position: [1.5, 2.5, 3.5],
                quaternion: [0.0, 0.0, 0.0, 1.0],
            },
        )
        .unwrap(),
    );
    server.send(
        &Message::new(
            "STATUS",
            "Stat",
            Body::Status(Status {
                code: 1,
                subcode: 42,
                error_name: Name::new("NoError").unwrap(),
                message: "all good".into(),
            }),
        )
        .unwrap(),
    );
    server.send(
        &Message::new(
            "TDATA",
            "Tracker",
            Body::TData(vec![
                TDataElement {
                    name: DeviceName::new("HeadToTracker").unwrap(),
                    kind: 2,
                    matrix: transform_floats(&p),
                },
                TDataElement {
                    name: DeviceName::new("CoilToTracker").unwrap(),
                    kind: 2,
                    matrix: transform_floats(&far),
                },
            ]),
        )
        .unwrap(),
    );
    // Everything written to the socket before closing it: the client reads it all before it
    // sees the end of the stream.
    assert!(
        server.flush(Duration::from_secs(10)),
        "{:?}",
        server.counters()
    );
    server.stop(); // ReceiveClient exits when the connection closes
    let deadline = Instant::now() + Duration::from_secs(20);
    while child.0.try_wait().unwrap().is_none() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(10));
    }
    // Headers and status go to stderr, matrices (igtl::PrintMatrix) to stdout.
    let mut err = String::new();
    std::io::Read::read_to_string(child.0.stderr.as_mut().unwrap(), &mut err).unwrap();
    std::io::Read::read_to_string(child.0.stdout.as_mut().unwrap(), &mut err).unwrap();
    for needle in [
        "Time stamp: 1700000000.500000000",
        "0.877583, -0.479426, 0, 11",
        "0, 0, 1, 33",
        "position   = (1.5, 2.5, 3.5)",
        " Code      : 1",
        " SubCode   : 42",
        " Error Name: NoError",
        " Status    : all good",
        " Name       : HeadToTracker",
        " Name       : CoilToTracker",
    ] {
        assert!(
            err.contains(needle),
            "C++ ReceiveClient output lacks {needle:?}:\n{err}"
        );
    }
    assert_eq!(
        err.matches("Receiving TRANSFORM data type.").count(),
        2,
        "both TRANSFORM headers read:\n{err}"
    );
    assert!(
        !err.contains("555"),
        "the corrupted TRANSFORM was printed: its CRC check failed to reject it\n{err}"
    );
    assert!(
        err.contains("0, 0, 1, 777"),
        "the TDATA tool at 777 mm (good CRC) is printed\n{err}"
    );
}

#[test]
fn the_cpp_tracker_server_streams_to_our_client() {
    let exe = peer("TrackerServer");
    // Port 0: the server binds whatever is free and we read which from /proc (the example
    // does not print it), so no other process can take it in between.
    let server = Killed(
        Command::new(&exe)
            .args(["0", "200"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let port = listening_port(server.0.id());
    let mut cfg = ClientConfig::new(&format!("127.0.0.1:{port}"));
    cfg.device = Some("Tracker".into());
    cfg.keep_messages = 1000;
    let client = Client::start(cfg, Arc::new(MonotonicClock::new()));
    let rx = client.take_messages().unwrap();
    let mut got = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    while got.len() < 100 && Instant::now() < deadline {
        if let Ok(r) = rx.recv_timeout(Duration::from_millis(100)) {
            got.push(r);
        }
    }
    assert_eq!(got.len(), 100, "{:?}", client.counters());
    for (k, r) in got.iter().enumerate() {
        let m = &r.message;
        assert_eq!(
            (m.type_name.as_str(), m.device.as_str(), m.header_version),
            ("TRANSFORM", "Tracker", 1)
        );
        assert!(m.timestamp.is_none(), "TrackerServer sends timestamp 0");
        assert!(
            (r.acquired_s - r.received_s).abs() < 1e-12,
            "receive time used for timestamp 0"
        );
        let Body::Transform(f) = &m.body else {
            panic!()
        };
        // GetRandomTestMatrix: position (50 cos φ, 50 sin φ, 50 cos φ) with φ = 0.2·k, in floats.
        // φ accumulates in a float, as the example does.
        let phi = f64::from((0..k).fold(0.0f32, |p, _| p + 0.2));
        let expected = [50.0 * phi.cos(), 50.0 * phi.sin(), 50.0 * phi.cos()];
        for a in 0..3 {
            assert!(
                (f64::from(f[9 + a]) - expected[a]).abs() < 1e-3,
                "message {k}: {:?} vs {expected:?}",
                &f[9..]
            );
        }
    }
    let n = client.counters();
    assert_eq!(n.crc_errors, 0);
    assert!(n.zero_timestamps >= 100);
    let sample = client.pose_source().latest().unwrap();
    assert!(sample.valid, "TrackerServer's matrices are rigid");
}
