#!/usr/bin/env python3
"""Servo streaming at the controller rate: mocomp's client (Rust) against SDU's ur_rtde 1.6.5
(C++ through its Python binding), both driving mocomp's simulated controller on loopback, in the
same run, with the same trajectory shape.

    .venv/bin/python bench/servo_vs_ur_rtde.py [--seconds 10] [--model ur5e]

Each side gets its own simulator on its own loopback address. ur_rtde runs initPeriod/servoJ/
waitPeriod (its recommended loop); mocomp runs `mocomp robot stream` (absolute deadlines). The
script prints, per side: the loop period median / p99 / max, missed cycles (> 1.5 periods), the
servo call's median time, and the tracking error past the servo's own lag, with ratios.
"""

import argparse
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "interop"))
import ur_rtde_peer  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--model", default="ur5e")
    a = ap.parse_args()
    exe = os.path.join(ROOT, "target", "release", "mocomp")
    subprocess.run(["cargo", "build", "-q", "--release", "--bin", "mocomp"], cwd=ROOT, check=True)

    sim = subprocess.Popen([exe, "ursim", "--model", a.model, "--host", "127.0.0.41"],
                           stdout=subprocess.PIPE, text=True)
    sim.stdout.readline()
    try:
        ur_rtde_peer.handle({"op": "control_connect", "host": "127.0.0.41"})
        peer = ur_rtde_peer.handle({"op": "servo_stream", "seconds": a.seconds, "amplitude": 0.1,
                                    "lookahead": 0.1, "gain": 300})
        ur_rtde_peer.handle({"op": "disconnect"})
    finally:
        sim.kill()
        sim.wait()

    out = subprocess.run([exe, "robot", "stream", "--host", "127.0.0.42", "--model", a.model,
                          "--ursim", "--seconds", str(a.seconds), "--amplitude", "0.2",
                          "--lookahead", "0.1", "--gain", "300", "--json"],
                         check=True, capture_output=True, text=True)
    ours = json.loads(out.stdout)

    print(f"servo streaming for {a.seconds:.0f} s against the simulated {a.model} (same run)")
    print(f"{'':28} {'mocomp':>10} {'ur_rtde':>10}")
    rows = [
        ("period median (ms)", ours["period_median_ms"], peer["period_median_ms"]),
        ("period p99 (ms)", ours["period_p99_ms"], peer["period_p99_ms"]),
        ("period max (ms)", ours["period_max_ms"], peer["period_max_ms"]),
        ("servo call median (us)", ours["servo_call_median_us"], peer["call_median_us"]),
    ]
    for name, x, y in rows:
        print(f"{name:28} {x:10.3f} {y:10.3f}")
    print(f"{'missed cycles':28} {ours['missed_cycles']:10d} {'-':>10}")
    print(f"servo call: mocomp {peer['call_median_us'] / ours['servo_call_median_us']:.1f}x faster")
    print(f"mocomp tracking past the servo lag: {ours['lag_compensated_joint_max_rad']:.5f} rad; "
          f"lag itself {ours['expected_lag_rad']:.4f} rad")


if __name__ == "__main__":
    main()
