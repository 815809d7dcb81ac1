//! A session recorded as MCAP with the ROS 2 profile: the ROS 2 node's topics (`/joint_states`,
//! `/tf`, `/mocomp/coil_pose`, `/mocomp/head_pose`, `/diagnostics`) and every cycle record
//! (`/mocomp/cycle`, `mocomp_msgs/msg/CycleRecord`), each message CDR-encoded as ROS 2 sends it,
//! each schema the message's `.msg` definition (`ros2msg`). Foxglove, `ros2 bag` and the MCAP
//! readers open it. Writing is the caller's thread's (never the loop's: the logger's).
//!
//! **Limits.** Writes and reads MCAP files only: it knows the messages, not the loop or ROS 2's
//! network.

use mocomp_ros2::CycleMessages;
use mocomp_ros2::msg::{CdrError, DiagnosticArray, RosMessage, TypeName, to_cdr};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

/// `mocomp_msgs/msg/CycleRecord`: one cycle of the loop, as its CSV log has it (SI units).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CycleRecordMsg {
    /// Loop time, s.
    pub t_s: f64,
    /// Which controller ran the cycle: `mocomp`, or `paper` (the paper's pipeline, in
    /// `mocomp demo`).
    pub controller: String,
    /// The mode after the cycle (`tracking`, `holding (Operator)`, …).
    pub mode: String,
    /// The cycle's event, if any.
    pub event: String,
    /// Age of the newest tracker sample, s.
    pub sample_age_s: f64,
    /// Prediction horizon, s.
    pub horizon_s: f64,
    /// Command delay, s.
    pub command_delay_s: f64,
    /// Head speed, m/s.
    pub head_speed_m_s: f64,
    /// Head angular speed, rad/s.
    pub head_speed_rad_s: f64,
    /// The measured flange's deviation from its goal, m.
    pub deviation_m: f64,
    /// Its angle, rad.
    pub deviation_rad: f64,
    /// The measured coil's error against its goal, m.
    pub coil_error_m: f64,
    /// Joints commanded, rad.
    pub q_command: [f64; 6],
    /// Joints measured, rad.
    pub q_actual: [f64; 6],
    /// Contact force, N (NaN without force sensing).
    pub contact_force_n: f64,
    /// The cycle's compute time, ns.
    pub compute_ns: u64,
    /// The dose the measured coil gives at the goal's target, V/m (NaN without a coil model).
    pub dose_v_per_m: f64,
    /// The same, % of the goal's planned dose.
    pub dose_pct: f64,
}

impl ros2_client::Message for CycleRecordMsg {}
impl RosMessage for CycleRecordMsg {
    const TYPE: TypeName = TypeName {
        package: "mocomp_msgs",
        name: "CycleRecord",
    };
    const DEFINITION: &'static str = "float64 t_s\nstring controller\nstring mode\nstring event\nfloat64 sample_age_s\nfloat64 horizon_s\nfloat64 command_delay_s\nfloat64 head_speed_m_s\nfloat64 head_speed_rad_s\nfloat64 deviation_m\nfloat64 deviation_rad\nfloat64 coil_error_m\nfloat64[6] q_command\nfloat64[6] q_actual\nfloat64 contact_force_n\nuint64 compute_ns\nfloat64 dose_v_per_m\nfloat64 dose_pct\n";
}

/// Why a recording could not be written.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file.
    #[error("{path}: {source}")]
    File {
        /// The file.
        path: String,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// MCAP's writer refused.
    #[error("MCAP: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A message did not encode.
    #[error(transparent)]
    Cdr(#[from] CdrError),
}

/// The recording's channels, by topic.
#[derive(Debug, Clone, Copy)]
struct Channels {
    joints: u16,
    tf: u16,
    coil: u16,
    head: u16,
    diagnostics: u16,
    cycle: u16,
}

/// An MCAP recording being written.
pub struct Recorder<W: Write + Seek> {
    w: mcap::Writer<W>,
    ch: Channels,
    seq: u32,
    messages: u64,
}

impl<W: Write + Seek> std::fmt::Debug for Recorder<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Recorder")
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

fn channel<M: RosMessage, W: Write + Seek>(
    w: &mut mcap::Writer<W>,
    topic: &str,
) -> Result<u16, RecordError> {
    let schema = w.add_schema(&M::TYPE.ros(), "ros2msg", M::DEFINITION.as_bytes())?;
    Ok(w.add_channel(schema, topic, "cdr", &BTreeMap::new())?)
}

impl Recorder<BufWriter<std::fs::File>> {
    /// Creates the file at `path` (replacing one there).
    pub fn create(path: &Path) -> Result<Self, RecordError> {
        let f = std::fs::File::create(path).map_err(|source| RecordError::File {
            path: path.display().to_string(),
            source,
        })?;
        Self::new(BufWriter::new(f))
    }
}

impl<W: Write + Seek> Recorder<W> {
    /// A recording written to `out`.
    pub fn new(out: W) -> Result<Self, RecordError> {
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .library("mocomp")
            .compression(None)
            .create(out)?;
        use mocomp_ros2::msg::{JointState, PoseStamped, TfMessage};
        let ch = Channels {
            joints: channel::<JointState, W>(&mut w, "/joint_states")?,
            tf: channel::<TfMessage, W>(&mut w, "/tf")?,
            coil: channel::<PoseStamped, W>(&mut w, "/mocomp/coil_pose")?,
            head: channel::<PoseStamped, W>(&mut w, "/mocomp/head_pose")?,
            diagnostics: channel::<DiagnosticArray, W>(&mut w, "/diagnostics")?,
            cycle: channel::<CycleRecordMsg, W>(&mut w, "/mocomp/cycle")?,
        };
        Ok(Self {
            w,
            ch,
            seq: 0,
            messages: 0,
        })
    }

    fn put<M: RosMessage>(&mut self, channel: u16, t_ns: u64, m: &M) -> Result<(), RecordError> {
        let data = to_cdr(m)?;
        self.seq = self.seq.wrapping_add(1);
        self.w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: self.seq,
                log_time: t_ns,
                publish_time: t_ns,
            },
            &data,
        )?;
        self.messages += 1;
        Ok(())
    }

    /// One cycle: its ROS 2 messages (when given: the node's rate may be lower) and its record,
    /// at `t_ns` (ns since the Unix epoch).
    pub fn cycle(
        &mut self,
        t_ns: u64,
        m: Option<&CycleMessages>,
        record: &CycleRecordMsg,
    ) -> Result<(), RecordError> {
        if let Some(m) = m {
            self.put(self.ch.joints, t_ns, &m.joints)?;
            self.put(self.ch.tf, t_ns, &m.tf)?;
            self.put(self.ch.coil, t_ns, &m.coil)?;
            if let Some(h) = &m.head {
                self.put(self.ch.head, t_ns, h)?;
            }
        }
        self.put(self.ch.cycle, t_ns, record)
    }

    /// The status, at `t_ns`.
    pub fn status(&mut self, t_ns: u64, d: &DiagnosticArray) -> Result<(), RecordError> {
        self.put(self.ch.diagnostics, t_ns, d)
    }

    /// Messages written.
    pub fn messages(&self) -> u64 {
        self.messages
    }

    /// Writes the summary and index, and flushes.
    pub fn finish(mut self) -> Result<u64, RecordError> {
        self.w.finish()?;
        Ok(self.messages)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)] // test code
    use super::*;
    use mocomp_geom::nalgebra::{Isometry3, Vector3};
    use mocomp_ros2::msg::{JointState, from_cdr};
    use mocomp_ros2::{Frames, Snapshot};

    #[test]
    fn a_recording_reads_back_every_message_with_its_schema() {
        let snapshot = Snapshot {
            stamp_unix_s: 1_700_000_000.5,
            q: [0.1, -1.3, 1.6, -1.87, -1.57, 0.0],
            qd: [0.0; 6],
            base_from_flange: Isometry3::identity(),
            base_from_coil: Isometry3::translation(0.0, 0.0, 0.05),
            base_from_tracker: Isometry3::new(Vector3::new(1.0, 0.1, 0.9), Vector3::z()),
            tracker_from_head: None,
            head_from_coil_goal: Isometry3::identity(),
        };
        let joints = mocomp_ros2::node::UR_JOINTS.map(String::from);
        let m = CycleMessages::of(&snapshot, &joints, &Frames::default());
        let mut buf = std::io::Cursor::new(Vec::new());
        let mut r = Recorder::new(&mut buf).unwrap();
        for k in 0..10u64 {
            let rec = CycleRecordMsg {
                t_s: k as f64 * 0.002,
                controller: "paper".into(),
                mode: "tracking".into(),
                q_actual: snapshot.q,
                compute_ns: k,
                ..CycleRecordMsg::default()
            };
            r.cycle(
                1_700_000_000_000_000_000 + k * 2_000_000,
                (k % 2 == 0).then_some(&m),
                &rec,
            )
            .unwrap();
        }
        assert_eq!(r.finish().unwrap(), 10 + 5 * 3);
        let bytes = buf.into_inner();
        let mut counts = BTreeMap::new();
        for msg in mcap::MessageStream::new(&bytes).unwrap() {
            let msg = msg.unwrap();
            let schema = msg.channel.schema.as_ref().unwrap();
            assert_eq!(schema.encoding, "ros2msg");
            assert_eq!(msg.channel.message_encoding, "cdr");
            *counts.entry(msg.channel.topic.clone()).or_insert(0) += 1;
            if msg.channel.topic == "/joint_states" {
                assert_eq!(schema.name, "sensor_msgs/msg/JointState");
                let js: JointState = from_cdr(&msg.data).unwrap();
                assert_eq!(js.position, snapshot.q.to_vec());
            }
            if msg.channel.topic == "/mocomp/cycle" {
                let c: CycleRecordMsg = from_cdr(&msg.data).unwrap();
                assert_eq!(
                    (c.controller.as_str(), c.mode.as_str()),
                    ("paper", "tracking")
                );
                assert_eq!(
                    msg.log_time,
                    1_700_000_000_000_000_000 + c.compute_ns * 2_000_000
                );
            }
        }
        assert_eq!(counts["/mocomp/cycle"], 10);
        assert_eq!(counts["/joint_states"], 5);
        assert_eq!(counts["/tf"], 5);
        assert!(!counts.contains_key("/mocomp/head_pose"), "no head known");
    }
}
