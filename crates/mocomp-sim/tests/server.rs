//! The simulated tracker served over OpenIGTLink, read by mocomp's own client as the loop reads
//! it: poses arrive at the rate, with the model's latency visible to a same-host receiver, and a
//! marker out of view arrives as invalid.

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code

use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_geom::{Clock, MonotonicClock, PoseSource, translation_error};
use mocomp_igtl::client::{Client, ClientConfig, TimestampMode};
use mocomp_sim::{TrackedMarker, TrackerModel, TrackerServer};
use mocomp_testkit::wait_until;
use std::sync::Arc;

#[test]
fn the_server_streams_each_marker_with_its_latency_and_validity() {
    let head = Isometry3::new(Vector3::new(0.1, -0.2, 0.9), Vector3::new(0.0, 0.3, 0.0));
    let model = TrackerModel {
        rate_hz: 100.0,
        latency_s: 0.03,
        noise_m: 0.0,
        noise_rad: 0.0,
        ..Default::default()
    };
    let markers = vec![
        TrackedMarker {
            device: "HeadToTracker".into(),
            truth: Box::new(move |_| Some(head)),
        },
        TrackedMarker {
            device: "ToolToTracker".into(),
            // Seen for the first 0.2 s only.
            truth: Box::new(move |t| (t < 0.2).then_some(head)),
        },
    ];
    let server = TrackerServer::start("127.0.0.1:0", model, markers).unwrap();
    let clock = Arc::new(MonotonicClock::new());
    let cfg = |device: &str| {
        let mut c = ClientConfig::new(&server.addr().to_string());
        c.device = Some(device.into());
        c.timestamps = TimestampMode::Synchronized;
        Client::start(c, clock.clone())
    };
    let head_client = cfg("HeadToTracker");
    let tool_client = cfg("ToolToTracker");
    let (mut heads, mut tools) = (head_client.pose_source(), tool_client.pose_source());
    wait_until("40 head poses", || head_client.counters().poses >= 40);
    let s = heads.latest().unwrap();
    assert!(s.valid);
    assert!(translation_error(&s.tracker_from_marker, &head) < 1e-6);
    let age = clock.now_s() - s.acquired_s;
    // At least the model's 30 ms latency (the point: a same-host receiver sees it); the upper
    // bound leaves a loaded machine 200 ms to deliver.
    assert!((0.03..0.25).contains(&age), "sample age {age}");
    // The tool went out of view after 0.2 s: its newest samples turn invalid.
    wait_until("the tool's samples to turn invalid", || {
        tools.latest().is_some_and(|t| !t.valid)
    });
}
