//! Delay from `Server::send` to the pose being available from the client's `PoseSource`, on
//! loopback, with a 1 kHz stream. `cargo bench -p mocomp-igtl --bench latency`.
//! Prints the median, 90th and 99th percentile and maximum of 5000 messages.
#![allow(missing_docs, clippy::unwrap_used, clippy::print_stdout)]

use mocomp_geom::PoseSource;
use mocomp_geom::nalgebra::{Isometry3, Vector3};
use mocomp_igtl::client::{Client, ClientConfig, MonotonicClock};
use mocomp_igtl::server::{Server, ServerConfig};
use mocomp_igtl::{Message, Timestamp};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn main() {
    // `cargo bench` passes "--bench"; `cargo test --benches` passes nothing: run briefly then.
    let full = std::env::args().any(|a| a == "--bench");
    let n = if full { 5000 } else { 200 };
    let server = Server::bind("127.0.0.1:0", ServerConfig::default()).unwrap();
    let mut cfg = ClientConfig::new(&server.local_addr().to_string());
    cfg.device = Some("HeadToTracker".into());
    let client = Client::start(cfg, Arc::new(MonotonicClock::new()));
    let mut source = client.pose_source();
    let start = Instant::now();
    while server.client_count() == 0 {
        assert!(start.elapsed() < Duration::from_secs(10), "no connection");
        std::thread::sleep(Duration::from_millis(1));
    }
    let mut delays = Vec::with_capacity(n);
    let mut lost = 0;
    let period = Duration::from_millis(1);
    let mut next = Instant::now();
    for k in 0..n {
        let pose = Isometry3::new(Vector3::new(0.1, 0.2, k as f64 * 1e-5), Vector3::zeros());
        let m = Message::transform("HeadToTracker", &pose, Timestamp::now()).unwrap();
        let sent = Instant::now();
        server.send(&m);
        loop {
            if source.latest().is_some() {
                delays.push(sent.elapsed().as_secs_f64() * 1e6);
                break;
            }
            if sent.elapsed() > Duration::from_millis(50) {
                lost += 1;
                break;
            }
            std::hint::spin_loop();
        }
        next += period;
        if let Some(wait) = next.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
    }
    delays.sort_by(f64::total_cmp);
    let q = |p: f64| delays[((delays.len() - 1) as f64 * p).round() as usize];
    println!(
        "send → PoseSource at 1 kHz on loopback, {} messages: median {:.1} µs, p90 {:.1} µs, p99 {:.1} µs, max {:.1} µs, lost {lost}",
        delays.len(),
        q(0.5),
        q(0.9),
        q(0.99),
        q(1.0)
    );
    println!("client counters: {:?}", client.counters());
}
