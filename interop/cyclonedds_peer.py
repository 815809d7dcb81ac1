"""Expose Cyclone DDS (PyPI `cyclonedds`, the DDS under ROS 2's rmw_cyclonedds_cpp) to mocomp's
tests, speaking ROS 2's DDS names and types as a ROS 2 node would.

Requests (one JSON line each; each may name its DDS "domain", default 0):
  {"op": "version"}                        -> {"version": "11.0.1"}
  {"op": "listen", "seconds": s, "wait": w, "idle": i}
      subscribes to rt/joint_states, rt/tf, rt/mocomp/coil_pose, rt/mocomp/head_pose and
      rt/diagnostics, waits up to w s for the first joint state, then reads for s seconds (with
      i: until nothing came for i s, at most s; every sample counted) ->
      {"counts": {topic: n}, "rates_hz": {topic: r}, "last"/"first": {topic: message as JSON},
       "latency_ms": {"median": m, "p99": p, "n": n}}  (joint states: receive time - header stamp)
  {"op": "wait_diag", "message": m, "wait": w}
      waits up to w s for an rt/diagnostics status whose message starts with m -> {"message",
      "level"} or {"error"}
  {"op": "publish_head", "topic": t, "rate_hz": r, "seconds": s, "frame": f,
   "pose": [x, y, z, qx, qy, qz, qw], "wait": w, "noise_m": n, "seed": k, "until_unmatched": u}
      waits up to w s for a subscriber to topic t, then publishes geometry_msgs/PoseStamped at r Hz
      for s seconds (with u: stops early once the matched subscriber has gone), each stamped now,
      its position with n m of Gaussian noise per axis (seeded by k) -> {"published": n,
      "matched": bool}

  {"op": "call", "service": "/mocomp/hold", "seq": n, "wait": w}
      calls a std_srvs/Trigger service as rmw_cyclonedds_cpp does -> {"success": b, "message": m}

Cyclone takes its configuration from CYCLONEDDS_URI; the test script runs this inside a network
namespace with only loopback, so discovery and data never leave the machine.
"""

import os
import random
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
from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32  # noqa: E402
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


# A service as rmw_cyclonedds_cpp maps it: request and reply topics whose samples start with
# the client's GUID (its last 8 bytes) and a sequence number.
@dataclass
class TriggerRequest(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Request_"):
    guid: array[uint8, 8] = field(default_factory=lambda: [0] * 8)
    seq_high: int32 = 0
    seq_low: uint32 = 0
    structure_needs_at_least_one_member: uint8 = 0


@dataclass
class TriggerResponse(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Response_"):
    guid: array[uint8, 8] = field(default_factory=lambda: [0] * 8)
    seq_high: int32 = 0
    seq_low: uint32 = 0
    success: bool = False
    message: str = ""


STATE = {"dp": {}, "services": {}}

TOPICS = {
    "joint_states": ("rt/joint_states", JointState, True),
    "tf": ("rt/tf", TFMessage, True),
    "coil_pose": ("rt/mocomp/coil_pose", PoseStamped, False),
    "head_pose": ("rt/mocomp/head_pose", PoseStamped, False),
    "diagnostics": ("rt/diagnostics", DiagnosticArray, True),
}


def dp(req=None):
    domain = int((req or {}).get("domain", 0))
    if domain not in STATE["dp"]:
        STATE["dp"][domain] = DomainParticipant(domain)
    return STATE["dp"][domain]


def qos(reliable):
    if reliable:
        # Keep all: the instrument must not drop what reached it while this process was not
        # scheduled (a busy machine); what it counts is then what the writer delivered.
        return Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)), Policy.History.KeepAll)
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
    p = dp(req)
    readers = {k: DataReader(p, Topic(p, name, t), qos=qos(rel)) for k, (name, t, rel) in TOPICS.items()}
    deadline = time.time() + float(req.get("wait", 10))
    counts = {k: 0 for k in readers}
    last = {}
    earliest = {}
    latency = []
    while time.time() < deadline:
        first = [s for s in readers["joint_states"].take(N=100) if type(s).__name__ != "InvalidSample"]
        if first:
            # Counted: with "idle" every sample is.
            counts["joint_states"] += len(first)
            last["joint_states"] = first[-1]
            earliest["joint_states"] = first[0]
            break
        time.sleep(0.002)
    seconds = float(req["seconds"])
    # With "idle": read until nothing new came for that long (the sender has stopped), at most
    # `seconds`: the counts then do not depend on how fast this machine is.
    idle = req.get("idle")
    start = time.time()
    end = start + seconds
    newest = start
    while time.time() < end:
        got = 0
        for k, r in readers.items():
            for s in r.take(N=1000):
                if type(s).__name__ == "InvalidSample":
                    # The writer went away (its instances unregistered): no data.
                    continue
                got += 1
                counts[k] += 1
                last[k] = s
                earliest.setdefault(k, s)
                if k == "joint_states":
                    latency.append((time.time() - stamp_s(s.header)) * 1e3)
        if got:
            newest = time.time()
        elif idle is not None and time.time() - newest > float(idle):
            break
        time.sleep(0.0005)
    seconds = max(1e-9, (newest if idle is not None else time.time()) - start)
    latency.sort()
    out = {
        "counts": counts,
        "rates_hz": {k: n / seconds for k, n in counts.items()},
        "last": {k: to_json(v) for k, v in last.items()},
        "first": {k: to_json(v) for k, v in earliest.items()},
    }
    if latency:
        out["latency_ms"] = {
            "median": statistics.median(latency),
            "p99": latency[min(len(latency) - 1, int(0.99 * (len(latency) - 1) + 0.5))],
            "n": len(latency),
        }
    return out


def wait_diag(req):
    """{"op": "wait_diag", "message": m, "wait": w} -> {"message": m, "level": l} once a
    diagnostics status says m (its first word(s)), or {"error": ...} after w s."""
    p = dp(req)
    if "diag" not in STATE:
        name, t, rel = TOPICS["diagnostics"]
        STATE["diag"] = DataReader(p, Topic(p, name, t), qos=qos(rel))
    r = STATE["diag"]
    deadline = time.time() + float(req.get("wait", 30))
    seen = []
    while time.time() < deadline:
        for s in r.take(N=100):
            if type(s).__name__ == "InvalidSample":
                continue
            for st in s.status:
                seen.append(st.message)
                if st.message.startswith(req["message"]):
                    return {"message": st.message, "level": st.level}
        time.sleep(0.01)
    return {"error": "no diagnostics saying %r; seen %r" % (req["message"], seen[-5:])}


def publish_head(req):
    p = dp(req)
    writer = DataWriter(p, Topic(p, "rt" + req["topic"], PoseStamped), qos=qos(False))
    deadline = time.time() + float(req.get("wait", 10))
    matched = False
    while time.time() < deadline:
        if writer.get_matched_subscriptions():
            matched = True
            break
        time.sleep(0.01)
    x, y, z, qx, qy, qz, qw = req["pose"]
    # A tracker's noise (a noiseless stream is a frozen one to a tracker's consumer), seeded.
    noise = float(req.get("noise_m", 0.0))
    rng = random.Random(int(req.get("seed", 1)))
    period = 1.0 / float(req["rate_hz"])
    n = 0
    end = time.time() + float(req["seconds"])
    nxt = time.time()
    until_unmatched = bool(req.get("until_unmatched", False))
    while time.time() < end:
        if until_unmatched and matched and not writer.get_matched_subscriptions():
            # The subscriber has gone (its run ended): nothing more to publish to.
            break
        now = time.time()
        sec = int(now)
        writer.write(PoseStamped(
            header=Header(stamp=Time(sec=sec, nanosec=int((now - sec) * 1e9)), frame_id=req.get("frame", "tracker")),
            pose=Pose(position=Point(x=x + rng.gauss(0, noise), y=y + rng.gauss(0, noise), z=z + rng.gauss(0, noise)), orientation=Quaternion(x=qx, y=qy, z=qz, w=qw))))
        n += 1
        nxt += period
        time.sleep(max(0.0, nxt - time.time()))
    return {"published": n, "matched": matched}


def call_trigger(req):
    """{"op": "call", "service": "/mocomp/hold", "seq": n, "wait": w} -> {"success", "message"}"""
    p = dp(req)
    name = req["service"]
    if name not in STATE["services"]:
        w = DataWriter(p, Topic(p, "rq" + name + "Request", TriggerRequest), qos=qos(True))
        r = DataReader(p, Topic(p, "rr" + name + "Reply", TriggerResponse), qos=qos(True))
        STATE["services"][name] = (w, r)
    w, r = STATE["services"][name]
    deadline = time.time() + float(req.get("wait", 10))
    while time.time() < deadline and not (w.get_matched_subscriptions() and r.get_matched_publications()):
        time.sleep(0.01)
    guid = list(range(1, 9))
    seq = int(req.get("seq", 1))
    # Matched on our side is not yet matched on the server's (discovery runs both ways): the
    # request is sent again every 200 ms until its reply comes, as a ROS 2 client waits for the
    # service to be available. The services asked here are idempotent.
    resend = 0.0
    while time.time() < deadline:
        if time.time() >= resend:
            w.write(TriggerRequest(guid=guid, seq_high=0, seq_low=seq))
            resend = time.time() + 0.2
        for s in r.take(N=10):
            if list(s.guid) == guid and s.seq_low == seq:
                return {"success": bool(s.success), "message": s.message}
        time.sleep(0.005)
    return {"error": "no reply"}


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": md.version("cyclonedds")}
    if op == "listen":
        return listen(req)
    if op == "wait_diag":
        return wait_diag(req)
    if op == "publish_head":
        return publish_head(req)
    if op == "call":
        return call_trigger(req)
    return {"error": f"unknown op {op!r}"}


if __name__ == "__main__":
    serve(handle)
