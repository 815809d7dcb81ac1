#!/usr/bin/env python3
"""Writes a seated head's motion as a tracker logs it when it only logs changes: samples 10-90 ms
apart while the head moves, one sample after a still spell of 1-5.6 s, each movement starting
from rest at up to 45 mm/s and 30 deg/s within 20 ms (one or two samples), nodding out and back
or turning and holding. Seeded: the same file every time.

usage: scripts/irregular_head_trace.py OUT.csv [--seed 33] [--seconds 60]
Columns: t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz (mocomp demo --motion-file). Standard library only.
"""

import argparse
import math
import random


def quat_mul(a, b):
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw)


def quat_axis_angle(axis, angle):
    s = math.sin(angle / 2)
    return (math.cos(angle / 2), axis[0] * s, axis[1] * s, axis[2] * s)


def unit(v):
    n = math.sqrt(sum(c * c for c in v))
    return [c / n for c in v]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--seed", type=int, default=33)
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args()
    rng = random.Random(a.seed)
    dt = 0.001
    pos = [0.0, 0.0, 250.0]
    q = (1.0, 0.0, 0.0, 0.0)
    t = 0.0
    rows = [(t, pos[:], q)]
    while t < a.seconds:
        # Still: one sample when the spell ends.
        t += rng.uniform(1.0, 5.6)
        rows.append((t, pos[:], q))
        # A movement: a nod out and back (or a turn that holds), from rest at once.
        speed = rng.uniform(25.0, 45.0)            # mm/s
        rate = math.radians(rng.uniform(15.0, 30.0))  # rad/s
        direction = unit([rng.gauss(0, 1) for _ in range(3)])
        # Back towards the start when the head has wandered.
        if math.dist(pos, [0.0, 0.0, 250.0]) > 15.0:
            direction = unit([0.0 - pos[0], 0.0 - pos[1], 250.0 - pos[2]])
        axis = unit([rng.gauss(0, 1) for _ in range(3)])
        # And back towards the first orientation when it has turned far.
        turned = 2 * math.acos(min(1.0, abs(q[0])))
        if turned > math.radians(12):
            back = [-c * (1 if q[0] >= 0 else -1) for c in q[1:]]
            axis = unit(back)
        out_and_back = rng.random() < 0.7
        duration = rng.uniform(0.4, 1.6)
        ramp = 0.02
        next_sample = t + rng.uniform(0.01, 0.09)
        k = 0.0
        while k < duration:
            # Velocity: up to full within `ramp`, reversed halfway for a nod.
            up = min(1.0, k / ramp, (duration - k) / ramp)
            sign = -1.0 if out_and_back and k > duration / 2 else 1.0
            v = speed * up * sign
            w = rate * up * sign
            for c in range(3):
                pos[c] += direction[c] * v * dt
            q = quat_mul(q, quat_axis_angle(axis, w * dt))
            k += dt
            if t + k >= next_sample:
                rows.append((t + k, pos[:], q))
                next_sample = t + k + rng.uniform(0.01, 0.09)
        t += duration
        rows.append((t, pos[:], q))
    with open(a.out, "w") as f:
        f.write("# a seated head's log: samples 10-90 ms apart while moving, one after each still\n")
        f.write(f"# spell of 1-5.6 s; onsets to 45 mm/s and 30 deg/s within 20 ms. Written by\n")
        f.write(f"# scripts/irregular_head_trace.py {a.out} --seed {a.seed} --seconds {a.seconds:g}\n")
        f.write("t_s,x_mm,y_mm,z_mm,qw,qx,qy,qz\n")
        for (t, p, q) in rows:
            n = math.sqrt(sum(c * c for c in q))
            f.write(f"{t:.4f},{p[0]:.3f},{p[1]:.3f},{p[2]:.3f},"
                    f"{q[0] / n:.6f},{q[1] / n:.6f},{q[2] / n:.6f},{q[3] / n:.6f}\n")


if __name__ == "__main__":
    main()
