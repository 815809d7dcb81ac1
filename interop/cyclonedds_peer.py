"""Expose Cyclone DDS (PyPI `cyclonedds`, the DDS under ROS 2's rmw_cyclonedds_cpp) to mocomp's
tests, speaking ROS 2's DDS names and types as a ROS 2 node would.

Requests (one JSON line each):
  {"op": "version"}                        -> {"version": "11.0.1"}
  {"op": "listen", "seconds": s, "wait": w}
      subscribes to rt/joint_states, rt/tf, rt/mocomp/coil_pose, rt/mocomp/head_pose and
      rt/diagnostics, waits up to w s for the first joint state, then reads for s seconds ->
      {"counts": {topic: n}, "rates_hz": {topic: r}, "last": {topic: message as JSON},
       "latency_ms": {"median": m, "p99": p, "n": n}}  (joint states: receive time - header stamp)
  {"op": "publish_head", "topic": t, "rate_hz": r, "seconds": s, "frame": f,
   "pose": [x, y, z, qx, qy, qz, qw], "wait": w}
      waits up to w s for a subscriber to topic t, then publishes geometry_msgs/PoseStamped at r Hz
      for s seconds, each stamped now -> {"published": n, "matched": bool}

Cyclone takes its configuration from CYCLONEDDS_URI; the test script runs this inside a network
namespace with only loopback, so discovery and data never leave the machine.
"""

import os
import statistics
from importlib import metadata as md
import time
from dataclasses import dataclass, field

# Loopback only, multicast on it (the test's network namespace has nothing else), unless the
# caller configured Cyclone itself.
os.environ.setdefault(
    "CYCLONEDDS_URI",
    '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="lo" multicast="true"/>'
    "</Interfaces></General></Domain></CycloneDDS>",
)

from cyclonedds.core import Qos, Policy  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import float64, int32, sequence, uint8, uint32  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

from jsonlines import serve  # noqa: E402


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32 = 0
    nanosec: uint32 = 0


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3 = field(default_factory=Vector3)
    rotation: Quaternion = field(default_factory=Quaternion)


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header = field(default_factory=Header)
    child_frame_id: str = ""
    transform: Transform = field(default_factory=Transform)


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped] = field(default_factory=list)


@dataclass
class KeyValue(IdlStruct, typename="diagnostic_msgs::msg::dds_::KeyValue_"):
    key: str = ""
    value: str = ""


@dataclass
class DiagnosticStatus(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticStatus_"):
    level: uint8 = 0
    name: str = ""
    message: str = ""
    hardware_id: str = ""
    values: sequence[KeyValue] = field(default_factory=list)


@dataclass
class DiagnosticArray(IdlStruct, typename="diagnostic_msgs::msg::dds_::DiagnosticArray_"):
    header: Header = field(default_factory=Header)
    status: sequence[DiagnosticStatus] = field(default_factory=list)


STATE = {"dp": None}

TOPICS = {
    "joint_states": ("rt/joint_states", JointState, True),
    "tf": ("rt/tf", TFMessage, True),
    "coil_pose": ("rt/mocomp/coil_pose", PoseStamped, False),
    "head_pose": ("rt/mocomp/head_pose", PoseStamped, False),
    "diagnostics": ("rt/diagnostics", DiagnosticArray, True),
}


def dp():
    if STATE["dp"] is None:
        STATE["dp"] = DomainParticipant(0)
    return STATE["dp"]


def qos(reliable):
    if reliable:
        return Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)), Policy.History.KeepLast(100))
    return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(100))


def to_json(x):
    if isinstance(x, list):
        return [to_json(v) for v in x]
    if hasattr(x, "__dataclass_fields__"):
        return {k: to_json(getattr(x, k)) for k in x.__dataclass_fields__}
    return x


def stamp_s(h):
    return h.stamp.sec + h.stamp.nanosec * 1e-9


def listen(req):
    readers = {k: DataReader(dp(), Topic(dp(), name, t), qos=qos(rel)) for k, (name, t, rel) in TOPICS.items()}
    deadline = time.time() + float(req.get("wait", 10))
    while time.time() < deadline and not readers["joint_states"].take(N=100):
        time.sleep(0.002)
    seconds = float(req["seconds"])
    counts = {k: 0 for k in readers}
    last = {}
    latency = []
    start = time.time()
    end = start + seconds
    while time.time() < end:
        for k, r in readers.items():
            for s in r.take(N=1000):
                counts[k] += 1
                last[k] = s
                if k == "joint_states":
                    latency.append((time.time() - stamp_s(s.header)) * 1e3)
        time.sleep(0.0005)
    latency.sort()
    out = {
        "counts": counts,
        "rates_hz": {k: n / seconds for k, n in counts.items()},
        "last": {k: to_json(v) for k, v in last.items()},
    }
    if latency:
        out["latency_ms"] = {
            "median": statistics.median(latency),
            "p99": latency[min(len(latency) - 1, int(0.99 * (len(latency) - 1) + 0.5))],
            "n": len(latency),
        }
    return out


def publish_head(req):
    writer = DataWriter(dp(), Topic(dp(), "rt" + req["topic"], PoseStamped), qos=qos(False))
    deadline = time.time() + float(req.get("wait", 10))
    matched = False
    while time.time() < deadline:
        if writer.get_matched_subscriptions():
            matched = True
            break
        time.sleep(0.01)
    x, y, z, qx, qy, qz, qw = req["pose"]
    period = 1.0 / float(req["rate_hz"])
    n = 0
    end = time.time() + float(req["seconds"])
    nxt = time.time()
    while time.time() < end:
        now = time.time()
        sec = int(now)
        writer.write(PoseStamped(
            header=Header(stamp=Time(sec=sec, nanosec=int((now - sec) * 1e9)), frame_id=req.get("frame", "tracker")),
            pose=Pose(position=Point(x=x, y=y, z=z), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))))
        n += 1
        nxt += period
        time.sleep(max(0.0, nxt - time.time()))
    return {"published": n, "matched": matched}


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": md.version("cyclonedds")}
    if op == "listen":
        return listen(req)
    if op == "publish_head":
        return publish_head(req)
    return {"error": f"unknown op {op!r}"}


if __name__ == "__main__":
    serve(handle)
