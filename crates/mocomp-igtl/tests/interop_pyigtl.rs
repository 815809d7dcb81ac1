//! Interop with pyigtl 0.3.4 (an independent Python implementation), both ways, header versions 1
//! and 2 with metadata.
//!
//! What this peer checks: message framing, the TRANSFORM matrix order and values, timestamps,
//! STRING, the extended header, metadata (keys, values, encodings) and message ids.
//! What it does not: pyigtl never verifies CRCs (our CRCs are checked against the C++ library and
//! the golden vectors instead), it silently drops STATUS and query messages, and it keeps only the
//! newest message per device name, so each case below uses its own device name. It also cannot
//! *send* non-ASCII metadata (its `encode_text` catches `UnicodeDecodeError` where encoding raises
//! `UnicodeEncodeError`, which kills its connection), so the metadata it sends here is ASCII; it
//! does decode our UTF-8 metadata (the "Zoë" case).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::nalgebra::{Isometry3, Matrix4, Vector3};
use mocomp_igtl::client::{Client, ClientConfig, MonotonicClock};
use mocomp_igtl::message::{Body, ENCODING_US_ASCII, Status, matrix_mm};
use mocomp_igtl::name::Name;
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, MetaEntry, Timestamp};
use mocomp_testkit::{PythonPeer, wait_until};
use serde_json::{Value, json};
use std::sync::Arc;
use std::time::Duration;

fn peer() -> PythonPeer {
    PythonPeer::start("pyigtl_peer.py", "pyigtl", "0.3.4")
}

fn pose() -> Isometry3<f64> {
    Isometry3::new(
        Vector3::new(0.0123, -0.0456, 0.789),
        Vector3::new(0.3, -0.2, 1.1),
    )
}

fn rows(m: &Matrix4<f64>) -> Vec<Vec<f64>> {
    (0..4)
        .map(|r| (0..4).map(|c| m[(r, c)]).collect())
        .collect()
}

fn matrix_of(v: &Value) -> Matrix4<f64> {
    Matrix4::from_fn(|r, c| v[r][c].as_f64().unwrap())
}

#[test]
fn pyigtl_server_to_our_client() {
    let mut py = peer();
    // pyigtl binds port 0 itself and reports the port it got.
    let port = py.request(&json!({"op": "server", "port": 0}))["port"]
        .as_u64()
        .unwrap();
    let mut cfg = ClientConfig::new(&format!("127.0.0.1:{port}"));
    cfg.device = Some("HeadToTracker".into());
    cfg.keep_messages = 100;
    let client = Client::start(cfg, Arc::new(MonotonicClock::new()));
    wait_until("pyigtl sees our client", || {
        py.request(&json!({"op": "connected"}))["connected"] == true
    });
    let m = mocomp_geom::matrix_mm_from_iso(&pose());
    let t = 1_700_000_000.25;
    py.request(&json!({"op": "send", "kind": "transform", "device": "HeadToTracker", "matrix": rows(&m), "timestamp": t, "header_version": 1}));
    py.request(&json!({"op": "send", "kind": "transform", "device": "CoilToTracker", "matrix": rows(&m), "timestamp": t + 1.0,
        "header_version": 2, "metadata": {"TransformStatus": "OK", "Patient": "Mueller"}, "message_id": 7}));
    py.request(&json!({"op": "send", "kind": "string", "device": "Note", "string": "hello from pyigtl", "timestamp": t + 2.0, "header_version": 2}));
    let rx = client.take_messages().unwrap();
    let got: Vec<_> = (0..3)
        .map(|_| {
            rx.recv_timeout(Duration::from_secs(10))
                .unwrap_or_else(|e| {
                    panic!("{e}: {:?}, {:?}", client.counters(), client.last_error())
                })
                .message
        })
        .collect();

    let h = &got[0];
    assert_eq!(
        (h.type_name.as_str(), h.device.as_str(), h.header_version),
        ("TRANSFORM", "HeadToTracker", 1)
    );
    let Body::Transform(f) = &h.body else {
        panic!("{:?}", h.body)
    };
    assert!(
        (matrix_mm(f) - m).amax() < 1e-4,
        "column-major order and values as pyigtl packs them"
    );
    assert!((h.timestamp.to_secs_f64() - t).abs() < 1e-6);

    let c = &got[1];
    assert_eq!((c.header_version, c.message_id), (2, 7));
    assert_eq!(c.meta("TransformStatus"), Some("OK"));
    let patient = c.metadata.iter().find(|e| e.key == "Patient").unwrap();
    assert_eq!(
        (patient.value_str(), patient.encoding),
        (Some("Mueller"), ENCODING_US_ASCII)
    );

    let s = &got[2];
    assert_eq!(
        s.body,
        Body::String {
            encoding: ENCODING_US_ASCII,
            text: b"hello from pyigtl".to_vec()
        }
    );
    let n = client.counters();
    assert_eq!(
        (n.crc_errors, n.disconnects, n.connections),
        (0, 0, 1),
        "{n:?}"
    );
    assert!(client.pose_source_latest_valid());
}

trait LatestValid {
    fn pose_source_latest_valid(&self) -> bool;
}
impl LatestValid for Client {
    fn pose_source_latest_valid(&self) -> bool {
        use mocomp_geom::PoseSource;
        self.pose_source().latest().is_some_and(|s| s.valid)
    }
}

#[test]
fn our_server_to_pyigtl_client() {
    let mut py = peer();
    let server = Server::bind("127.0.0.1:0", ServerConfig::default()).unwrap();
    py.request(&json!({"op": "client", "port": server.local_addr().port()}));
    wait_until("pyigtl connects", || server.client_count() == 1);
    let ts = Timestamp::from_secs_f64(1_700_000_123.5);
    server.send(&Message::transform("HeadToTracker", &pose(), ts).unwrap());
    let mut v2 = Message::transform("CoilToTracker", &pose(), ts)
        .unwrap()
        .with_metadata(vec![
            MetaEntry::text("TransformStatus", "OK"),
            MetaEntry::text("Operator", "Zoë"),
        ]);
    v2.message_id = 9;
    server.send(&v2);
    // pyigtl drops STATUS silently: the stream must stay in step for the STRING after it.
    server.send(
        &Message::new(
            "STATUS",
            "Tracker",
            Body::Status(Status {
                code: 1,
                subcode: 0,
                error_name: Name::empty(),
                message: "ok".into(),
            }),
        )
        .unwrap(),
    );
    server.send(
        &Message::new(
            "STRING",
            "Note",
            Body::String {
                encoding: 3,
                text: b"hello from mocomp".to_vec(),
            },
        )
        .unwrap(),
    );

    let h = py.request(&json!({"op": "wait", "device": "HeadToTracker", "timeout": 60}));
    assert_eq!(h["found"], true, "{h}");
    assert_eq!(h["header_version"], 1);
    assert!((matrix_of(&h["matrix"]) - mocomp_geom::matrix_mm_from_iso(&pose())).amax() < 1e-4);
    assert!((h["timestamp"].as_f64().unwrap() - 1_700_000_123.5).abs() < 1e-6);

    let c = py.request(&json!({"op": "wait", "device": "CoilToTracker", "timeout": 60}));
    assert_eq!(
        (c["header_version"].as_u64(), c["message_id"].as_u64()),
        (Some(2), Some(9))
    );
    assert_eq!(c["metadata"]["TransformStatus"], "OK");
    assert_eq!(c["metadata"]["Operator"], "Zoë");

    let s = py.request(&json!({"op": "wait", "device": "Note", "timeout": 60}));
    assert_eq!(s["string"], "hello from mocomp");
}
