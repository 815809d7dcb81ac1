"""mocomp as a ROS 2 node: how late Cyclone DDS sees the loop's joint states, and whether the node
costs the loop anything.

    cargo build --release --bin mocomp
    unshare --net -- sh -c 'ip link set lo up && ip link set lo multicast on &&
        ip route add 224.0.0.0/4 dev lo && .venv/bin/python bench/ros2_latency.py [--runs 3]'

(DDS discovers by multicast on every interface: run it in a network namespace with only
loopback, as the test script does; the script refuses to run otherwise.)

Each run pair, on examples/run-sim.toml (the simulated UR3e at 500 Hz, nodding head):
  A. `mocomp run --json` alone: the cycle's compute median and p99;
  B. `mocomp run --ros2 --json` with a Cyclone DDS reader (PyPI `cyclonedds`, the DDS under
     rmw_cyclonedds_cpp) on /joint_states: the same figures, and for every joint state the time
     from its header stamp (the robot state's reception, wall clock) to Cyclone's listener
     callback (wall clock, same machine).
Prints each run and the medians over runs.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "interop"))
import cyclonedds_peer as peer  # noqa: E402  (sets CYCLONEDDS_URI to loopback)
from cyclonedds.core import Listener  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
MOCOMP = os.path.join(ROOT, "target", "release", "mocomp")
CONFIG = os.path.join(ROOT, "examples", "run-sim.toml")


def loopback_only():
    with open("/proc/net/dev") as f:
        names = [line.split(":")[0].strip() for line in f.readlines()[2:]]
    return names == ["lo"]


def run(config, seconds, ros2):
    args = [MOCOMP, "run", "--config", config, "--seconds", str(seconds), "--quiet", "--json"]
    if ros2:
        args.append("--ros2")
    out = subprocess.run(args, capture_output=True, text=True, check=True,
                         env={**os.environ, "ROS_DOMAIN_ID": "41"})
    return json.loads(out.stdout)


def percentile(v, p):
    v = sorted(v)
    return v[min(len(v) - 1, int(p * (len(v) - 1) + 0.5))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=12.0)
    a = ap.parse_args()
    if not loopback_only():
        sys.exit("run this in a network namespace with only loopback (see the docstring)")
    with tempfile.TemporaryDirectory() as d:
        config = os.path.join(d, "run.toml")
        with open(CONFIG) as f:
            text = f.read().replace('host = "127.0.0.2"', 'host = "127.0.2.41"')
        with open(config, "w") as f:
            f.write(text)
        dp = peer.dp({"domain": 41})
        latencies = []

        class OnData(Listener):
            def on_data_available(self, reader):
                now = time.time()
                for s in reader.take(N=100):
                    # The writer's end arrives as an invalid sample: no stamp.
                    if isinstance(s, peer.JointState):
                        latencies.append((now - peer.stamp_s(s.header)) * 1e3)

        reader = DataReader(dp, Topic(dp, "rt/joint_states", peer.JointState), qos=peer.qos(True),
                            listener=OnData())
        rows = []
        for i in range(a.runs):
            off = run(config, a.seconds, False)
            del latencies[:]
            on = run(config, a.seconds, True)
            lat = list(latencies)
            row = {
                "off_compute_median_us": off["compute_median_us"],
                "off_compute_p99_us": off["compute_p99_us"],
                "on_compute_median_us": on["compute_median_us"],
                "on_compute_p99_us": on["compute_p99_us"],
                "joint_states_received": len(lat),
                "cycles": on["cycles"],
                "latency_median_ms": statistics.median(lat) if lat else float("nan"),
                "latency_p99_ms": percentile(lat, 0.99) if lat else float("nan"),
                "dropped": on["ros2"]["dropped"],
            }
            rows.append(row)
            print(json.dumps(row), flush=True)
        keys = rows[0].keys()
        print("medians over runs:", json.dumps({k: statistics.median(r[k] for r in rows) for k in keys}))
        del reader
        threading.Event().wait(0.1)


if __name__ == "__main__":
    main()
