//! mocomp's ROS 2 node, on its own thread.
//!
//! What the loop's side sends ([`Out`]: a cycle's [`Snapshot`], the once-a-second [`Status`])
//! goes through a bounded channel the sender never waits on; the node publishes it:
//! `/joint_states` (`sensor_msgs/JointState`), `/tf` (`tf2_msgs/TFMessage`: base → flange, base →
//! tracker, tracker → head, head → coil goal), `/mocomp/coil_pose` and `/mocomp/head_pose`
//! (`geometry_msgs/PoseStamped` in the base frame) and `/diagnostics`
//! (`diagnostic_msgs/DiagnosticArray`). It serves `/mocomp/hold` and `/mocomp/resume`
//! (`std_srvs/Trigger`) through a handler the application gives, and, with a head topic,
//! subscribes to `geometry_msgs/PoseStamped` head poses (the tracker frame; the header stamp is
//! the acquisition time) and publishes them in a lock-free cell a [`HeadSource`] reads.
//!
//! QoS as ROS 2's customs: `/tf` reliable, volatile, keep-last 100; `/joint_states` reliable;
//! the poses and the head topic best-effort (sensor data); diagnostics reliable.

use crate::convert;
use crate::cycle::{CycleMessages, Frames, Snapshot, Status};
use crate::msg::{
    DiagnosticArray, JointState, PoseStamped, RosMessage, TfMessage, TriggerRequest,
    TriggerResponse,
};
use mocomp_geom::{Clock, LatestCell, PoseSample, PoseSource, Watch};
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, Node, NodeName, NodeOptions, QosProfile,
    ServiceMapping, ServiceTypeName,
    qos::{Durability, History, Reliability},
};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::Duration;

/// The node's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct Ros2Config {
    /// The DDS domain (`ROS_DOMAIN_ID`).
    pub domain_id: u16,
    /// The node's name. [`mocomp`]
    pub node_name: String,
    /// The joints' names, base to wrist (UR's).
    pub joint_names: [String; 6],
    /// The frames.
    pub frames: Frames,
    /// Subscribe to head poses on this topic (`None`: no head source).
    pub head_topic: Option<String>,
    /// How services map onto DDS topics: ROS 2's DDS implementations differ.
    pub service_mapping: ServiceMappingName,
}

/// How ROS 2 services map onto DDS topics, which depends on the peer's DDS.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ServiceMappingName {
    /// RPC over DDS "Enhanced": Fast DDS (`rmw_fastrtps_cpp`, ROS 2's default).
    #[default]
    Enhanced,
    /// `rmw_cyclonedds_cpp`'s.
    Cyclone,
}

/// UR's joint names, as its ROS 2 driver publishes them.
pub const UR_JOINTS: [&str; 6] = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
];

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            domain_id: 0,
            node_name: "mocomp".into(),
            joint_names: UR_JOINTS.map(String::from),
            frames: Frames::default(),
            head_topic: None,
            service_mapping: ServiceMappingName::default(),
        }
    }
}

/// What the node is sent.
#[derive(Debug, Clone, PartialEq)]
pub enum Out {
    /// A cycle.
    Cycle(Box<Snapshot>),
    /// The status.
    Status(Status),
}

/// A service call the node received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Call {
    /// `/mocomp/hold`.
    Hold,
    /// `/mocomp/resume`.
    Resume,
}

/// The application's answer to a service call: `Ok(what was done)` or `Err(why not)`.
pub type Handler = Box<dyn FnMut(Call) -> Result<String, String> + Send>;

/// The node could not start.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// DDS or ROS 2 refused (the participant, a topic, a name).
    #[error("ROS 2: {what}: {detail}")]
    Dds {
        /// What was being made.
        what: String,
        /// Why.
        detail: String,
    },
    /// The thread could not be started.
    #[error("ROS 2: cannot start the node's thread: {0}")]
    Thread(#[source] std::io::Error),
}

fn dds(what: &str, e: impl std::fmt::Debug) -> Ros2Error {
    Ros2Error::Dds {
        what: what.to_string(),
        detail: format!("{e:?}"),
    }
}

/// Messages that may wait for the node (a cycle each, at up to 500 Hz).
const QUEUE: usize = 256;

/// The running node. Dropping it stops the thread.
pub struct Ros2Bridge {
    tx: Option<SyncSender<Out>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    head: Arc<LatestCell>,
    dropped: AtomicU64,
    published: Arc<AtomicU64>,
    watch: Arc<Watch>,
}

impl std::fmt::Debug for Ros2Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ros2Bridge")
            .field("dropped", &self.dropped.load(Ordering::Relaxed))
            .finish_non_exhaustive()
    }
}

/// The newest head pose from the subscribed topic, its acquisition time (the header's stamp)
/// mapped onto the loop's clock when it is read: the sender's clock and this machine's wall
/// clock are taken as synchronised, as ROS 2 does.
pub struct HeadSource {
    cell: Arc<LatestCell>,
    seen: u64,
    clock: Arc<dyn Clock>,
    watch: Arc<Watch>,
}

impl std::fmt::Debug for HeadSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HeadSource")
            .field("seen", &self.seen)
            .finish_non_exhaustive()
    }
}

impl HeadSource {
    /// Head poses the node has received so far (however often `latest` was asked).
    pub fn received(&self) -> u64 {
        self.cell.read().map_or(0, |(v, _)| v)
    }
}

impl PoseSource for HeadSource {
    fn latest(&mut self) -> Option<PoseSample> {
        let (v, mut s) = self.cell.read()?;
        if v == self.seen {
            return None;
        }
        self.seen = v;
        // The cell holds the stamp in Unix seconds.
        let age = unix_now() - s.acquired_s;
        s.acquired_s = self.clock.now_s() - age.max(0.0);
        Some(s)
    }

    fn failures(&self) -> u64 {
        self.watch.failures()
    }
}

fn unix_now() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(f64::NAN, |d| d.as_secs_f64())
}

impl Ros2Bridge {
    /// Creates the node (its DDS participant, publishers, services and the head subscription)
    /// and starts its thread.
    pub fn start(cfg: &Ros2Config, handler: Option<Handler>) -> Result<Self, Ros2Error> {
        let context = Context::with_options(ContextOptions::new().domain_id(cfg.domain_id))
            .map_err(|e| dds("the DDS participant", e))?;
        let node = context
            .new_node(
                NodeName::new("/", &cfg.node_name).map_err(|e| dds("the node's name", e))?,
                NodeOptions::new().enable_rosout(false),
            )
            .map_err(|e| dds("the node", e))?;
        let mut io = NodeIo::new(node, cfg, handler)?;
        let head = Arc::new(LatestCell::new());
        let (tx, rx) = sync_channel(QUEUE);
        let stop = Arc::new(AtomicBool::new(false));
        let published = Arc::new(AtomicU64::new(0));
        let watch = Arc::new(Watch::new());
        let thread = {
            let (stop, head, published, watch) = (
                Arc::clone(&stop),
                Arc::clone(&head),
                Arc::clone(&published),
                Arc::clone(&watch),
            );
            std::thread::Builder::new()
                .name("mocomp-ros2".into())
                .spawn(move || {
                    // Keep the context alive as long as the node.
                    let _context = context;
                    // A panic in the node's work (a message it could not take, the
                    // application's handler) is counted and named, and the node goes on: its
                    // topics and services stay, only that one item is lost.
                    while !stop.load(Ordering::Relaxed) {
                        if watch
                            .run("mocomp-ros2", || io.run(&rx, &stop, &head, &published))
                            .is_some()
                        {
                            break;
                        }
                    }
                })
                .map_err(Ros2Error::Thread)?
        };
        Ok(Self {
            tx: Some(tx),
            stop,
            thread: Some(thread),
            head,
            dropped: AtomicU64::new(0),
            published,
            watch,
        })
    }

    /// Times the node's thread failed (a panic) and went on; the last failure in words.
    pub fn failures(&self) -> (u64, Option<String>) {
        (self.watch.failures(), self.watch.last())
    }

    /// Sends `out` to the node; never waits (a full queue drops it and counts it).
    pub fn send(&self, out: Out) {
        if let Some(tx) = &self.tx
            && let Err(TrySendError::Full(_)) = tx.try_send(out)
        {
            self.dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// Messages the node could not take in time.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// Messages published so far.
    pub fn published(&self) -> u64 {
        self.published.load(Ordering::Relaxed)
    }

    /// The head poses received on the head topic, on `clock` (the loop's).
    pub fn head_source(&self, clock: Arc<dyn Clock>) -> HeadSource {
        HeadSource {
            cell: Arc::clone(&self.head),
            seen: 0,
            clock,
            watch: Arc::clone(&self.watch),
        }
    }
}

impl Drop for Ros2Bridge {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.tx = None;
        if let Some(t) = self.thread.take() {
            t.join().ok();
        }
    }
}

fn qos(reliable: bool, depth: usize) -> QosProfile {
    let q = QosProfile::publisher_default()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth });
    if reliable {
        q.reliability(Reliability::Reliable {
            when_full: ros2_client::qos::WhenFull::DEFAULT,
        })
    } else {
        q.reliability(Reliability::BestEffort)
    }
}

/// The node's publishers, servers and subscription.
struct NodeIo {
    _node: Node,
    cfg: Ros2Config,
    joints: ros2_client::Publisher<JointState>,
    tf: ros2_client::Publisher<TfMessage>,
    coil: ros2_client::Publisher<PoseStamped>,
    head: ros2_client::Publisher<PoseStamped>,
    diagnostics: ros2_client::Publisher<DiagnosticArray>,
    servers: Vec<(Call, ros2_client::Server<TriggerRequest, TriggerResponse>)>,
    handler: Option<Handler>,
    head_in: Option<ros2_client::Subscription<PoseStamped>>,
}

fn topic_name(name: &str) -> Result<Name, Ros2Error> {
    let (ns, base) = match name.rsplit_once('/') {
        Some(("", b)) => ("/", b),
        Some((ns, b)) => (ns, b),
        None => ("/", name),
    };
    Name::new(ns, base).map_err(|e| dds(&format!("the name {name:?}"), e))
}

fn publisher<M: RosMessage>(
    node: &mut Node,
    name: &str,
    q: &QosProfile,
) -> Result<ros2_client::Publisher<M>, Ros2Error> {
    let t = M::TYPE;
    let topic = node
        .create_topic(
            &topic_name(name)?,
            MessageTypeName::new(t.package, t.name),
            q,
        )
        .map_err(|e| dds(&format!("the topic {name}"), e))?;
    node.create_publisher::<M>(&topic, Some(q.clone()))
        .map_err(|e| dds(&format!("the publisher of {name}"), e))
}

impl NodeIo {
    fn new(mut node: Node, cfg: &Ros2Config, handler: Option<Handler>) -> Result<Self, Ros2Error> {
        let reliable = qos(true, 10);
        let sensor = qos(false, 5);
        let joints = publisher(&mut node, "/joint_states", &reliable)?;
        let tf = publisher(&mut node, "/tf", &qos(true, 100))?;
        let coil = publisher(&mut node, "/mocomp/coil_pose", &sensor)?;
        let head = publisher(&mut node, "/mocomp/head_pose", &sensor)?;
        let diagnostics = publisher(&mut node, "/diagnostics", &reliable)?;
        let mut servers = Vec::new();
        if handler.is_some() {
            for (call, name) in [
                (Call::Hold, "/mocomp/hold"),
                (Call::Resume, "/mocomp/resume"),
            ] {
                let server = node
                    .create_server::<TriggerRequest, TriggerResponse>(
                        match cfg.service_mapping {
                            ServiceMappingName::Enhanced => ServiceMapping::Enhanced,
                            ServiceMappingName::Cyclone => ServiceMapping::Cyclone,
                        },
                        &topic_name(name)?,
                        &ServiceTypeName::new("std_srvs", "Trigger"),
                        reliable.clone(),
                        reliable.clone(),
                    )
                    .map_err(|e| dds(&format!("the service {name}"), e))?;
                servers.push((call, server));
            }
        }
        let head_in = match &cfg.head_topic {
            Some(name) => {
                let t = PoseStamped::TYPE;
                let topic = node
                    .create_topic(
                        &topic_name(name)?,
                        MessageTypeName::new(t.package, t.name),
                        &sensor,
                    )
                    .map_err(|e| dds(&format!("the topic {name}"), e))?;
                Some(
                    node.create_subscription::<PoseStamped>(&topic, Some(sensor.clone()))
                        .map_err(|e| dds(&format!("the subscription to {name}"), e))?,
                )
            }
            None => None,
        };
        Ok(Self {
            _node: node,
            cfg: cfg.clone(),
            joints,
            tf,
            coil,
            head,
            diagnostics,
            servers,
            handler,
            head_in,
        })
    }

    fn run(
        &mut self,
        rx: &Receiver<Out>,
        stop: &AtomicBool,
        head: &LatestCell,
        published: &AtomicU64,
    ) {
        while !stop.load(Ordering::Relaxed) {
            // Head poses and service calls at least every millisecond; what the loop sends as
            // it comes.
            match rx.recv_timeout(Duration::from_millis(1)) {
                Ok(out) => {
                    let n = self.publish(&out);
                    published.fetch_add(n, Ordering::Relaxed);
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
            self.take_head(head);
            self.serve();
        }
    }

    /// Publishes one item; returns how many messages went out.
    fn publish(&self, out: &Out) -> u64 {
        match out {
            Out::Cycle(snapshot) => {
                let m = CycleMessages::of(snapshot, &self.cfg.joint_names, &self.cfg.frames);
                let mut n = u64::from(self.joints.publish(m.joints).is_ok());
                n += u64::from(self.tf.publish(m.tf).is_ok());
                n += u64::from(self.coil.publish(m.coil).is_ok());
                if let Some(head) = m.head {
                    n += u64::from(self.head.publish(head).is_ok());
                }
                n
            }
            Out::Status(st) => u64::from(
                self.diagnostics
                    .publish(st.message(&self.cfg.node_name))
                    .is_ok(),
            ),
        }
    }

    /// The newest head poses, into the cell with their stamps (Unix seconds).
    fn take_head(&mut self, cell: &LatestCell) {
        let Some(sub) = &self.head_in else { return };
        while let Ok(Some((m, _))) = sub.take() {
            let Ok(pose) = convert::iso(&m.pose) else {
                // Not a pose: the loop's tracker rules see no new sample (a stale stream holds).
                continue;
            };
            cell.publish(&PoseSample {
                tracker_from_marker: pose,
                acquired_s: convert::seconds(&m.header.stamp),
                valid: true,
                error_m: f64::NAN,
            });
        }
    }

    fn serve(&mut self) {
        let Some(handler) = self.handler.as_mut() else {
            return;
        };
        for (call, server) in &self.servers {
            while let Ok(Some((id, _req))) = server.receive_request() {
                let response = match handler(*call) {
                    Ok(what) => TriggerResponse {
                        success: true,
                        message: what,
                    },
                    Err(why) => TriggerResponse {
                        success: false,
                        message: why,
                    },
                };
                server.send_response(id, response).ok();
            }
        }
    }
}
