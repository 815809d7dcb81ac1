//! The node's hold and resume services in both of ROS 2's service mappings, called by a ROS 2
//! client of another DDS participant: the "enhanced" mapping (Fast DDS's, `rmw_fastrtps_cpp`, ROS
//! 2's default) has no third-party peer that installs without ROS (Fast DDS's Python bindings are
//! not on PyPI), so its client is `ros2-client`'s own; the Cyclone mapping is also checked against
//! Cyclone DDS itself (`mocomp-cli`'s `ros2` test). Each call reaches the application's handler
//! once, and its answer comes back. In the test script's network namespace (loopback only).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::print_stderr
)] // test code

use mocomp_ros2::msg::{TriggerRequest, TriggerResponse};
use mocomp_ros2::node::{Call, Handler, ServiceMappingName};
use mocomp_ros2::{Ros2Bridge, Ros2Config};
use mocomp_testkit::assert_loopback_only;
use ros2_client::qos::{Durability, History, Reliability};
use ros2_client::{
    Context, ContextOptions, Name, NodeName, NodeOptions, QosProfile, ServiceMapping,
    ServiceTypeName,
};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A `std_srvs/Trigger` client of `/mocomp/<service>`, with ROS 2's default service QoS.
fn trigger_client(
    node: &mut ros2_client::Node,
    mapping: ServiceMapping,
    service: &str,
) -> ros2_client::Client<TriggerRequest, TriggerResponse> {
    let qos = QosProfile::publisher_default()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
        .reliability(Reliability::Reliable {
            when_full: ros2_client::qos::WhenFull::DEFAULT,
        });
    node.create_client::<TriggerRequest, TriggerResponse>(
        mapping,
        &Name::new("/mocomp", service).unwrap(),
        &ServiceTypeName::new("std_srvs", "Trigger"),
        qos.clone(),
        qos,
    )
    .unwrap()
}

/// Calls `service` until it answers (discovery takes a moment; a request sent before it is
/// lost, so it is sent again each half second), for at most 20 s.
fn call(node: &mut ros2_client::Node, mapping: ServiceMapping, service: &str) -> TriggerResponse {
    let client = trigger_client(node, mapping, service);
    let end = Instant::now() + Duration::from_secs(20);
    while Instant::now() < end {
        let id = client.send_request(TriggerRequest::default()).unwrap();
        let resend = Instant::now() + Duration::from_millis(500);
        while Instant::now() < resend {
            if let Ok(Some((rid, response))) = client.receive_response()
                && rid == id
            {
                return response;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    panic!("/mocomp/{service} did not answer in 20 s");
}

fn served_in(mapping: ServiceMappingName, client_mapping: ServiceMapping, domain_id: u16) {
    assert_loopback_only();
    let calls = Arc::new(Mutex::new(Vec::new()));
    let handler: Handler = {
        let calls = Arc::clone(&calls);
        Box::new(move |c: Call| {
            calls.lock().unwrap().push(c);
            // Resume is refused, as the application refuses a call it cannot take.
            match c {
                Call::Hold => Ok("hold requested".into()),
                Call::Resume => Err("the loop has ended".into()),
            }
        })
    };
    let cfg = Ros2Config {
        domain_id,
        service_mapping: mapping,
        ..Ros2Config::default()
    };
    let _bridge = Ros2Bridge::start(&cfg, Some(handler)).unwrap();
    let context = Context::with_options(ContextOptions::new().domain_id(domain_id)).unwrap();
    let mut node = context
        .new_node(
            NodeName::new("/", "services_test").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    let hold = call(&mut node, client_mapping, "hold");
    assert!(hold.success, "{hold:?}");
    assert_eq!(hold.message, "hold requested");
    let resume = call(&mut node, client_mapping, "resume");
    assert!(!resume.success, "{resume:?}");
    assert_eq!(resume.message, "the loop has ended");
    // A request resent before its answer came may have been served twice; in order, though.
    let seen = calls.lock().unwrap().clone();
    assert_eq!(seen.first(), Some(&Call::Hold), "{seen:?}");
    assert_eq!(seen.last(), Some(&Call::Resume), "{seen:?}");
}

#[test]
fn hold_and_resume_answer_a_client_in_the_enhanced_mapping() {
    served_in(ServiceMappingName::Enhanced, ServiceMapping::Enhanced, 24);
}

#[test]
fn hold_and_resume_answer_a_client_in_the_cyclone_mapping() {
    served_in(ServiceMappingName::Cyclone, ServiceMapping::Cyclone, 25);
}

#[test]
fn a_handler_that_panics_is_a_named_failure_and_the_node_goes_on() {
    // A fault injected into the node's thread: the application's handler panics on hold. The
    // node counts and names it, the head source reports it to the loop, and the next call is
    // served.
    assert_loopback_only();
    let handler: Handler = Box::new(|c: Call| match c {
        Call::Hold => panic!("injected: the handler failed on hold"),
        Call::Resume => Ok("resume requested".into()),
    });
    let cfg = Ros2Config {
        domain_id: 26,
        service_mapping: ServiceMappingName::Enhanced,
        ..Ros2Config::default()
    };
    let bridge = Ros2Bridge::start(&cfg, Some(handler)).unwrap();
    let head = bridge.head_source(Arc::new(mocomp_geom::MonotonicClock::new()));
    let context = Context::with_options(ContextOptions::new().domain_id(26)).unwrap();
    let mut node = context
        .new_node(
            NodeName::new("/", "failing_handler_test").unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    // The hold's request is taken and the handler panics: no answer comes; the node goes on.
    let client = trigger_client(&mut node, ServiceMapping::Enhanced, "hold");
    let end = Instant::now() + Duration::from_secs(30);
    while bridge.failures().0 == 0 {
        assert!(Instant::now() < end, "the hold never reached the handler");
        client.send_request(TriggerRequest::default()).unwrap();
        std::thread::sleep(Duration::from_millis(200));
    }
    let (n, last) = bridge.failures();
    assert!(n >= 1);
    let last = last.unwrap_or_default();
    assert!(
        last.contains("mocomp-ros2 panicked") && last.contains("injected: the handler failed"),
        "{last}"
    );
    use mocomp_geom::PoseSource;
    assert_eq!(head.failures(), n, "the loop sees it");
    let resume = call(&mut node, ServiceMapping::Enhanced, "resume");
    assert!(resume.success, "{resume:?}");
    assert_eq!(resume.message, "resume requested");
}
