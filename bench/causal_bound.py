"""How well any causal predictor could do on a recorded head trace, given the head's true state now.

    .venv/bin/python bench/causal_bound.py examples/head-irregular-60s.csv [--horizons-ms 30,58]

The oracle of `mocomp demo --controllers oracle` knows the future. A real loop knows only the
past, and must carry the head over the horizon (the tracker's latency, the servo's lag, the
command's delay: about 58 ms on the demo's CB3). This replays the trace as the demo does (a
monotone cubic in position and in rotation vector) and extrapolates, from the head's *true*
pose, velocity and acceleration at each instant (no noise, no filter lag), to the horizon:
holding the pose, at constant velocity, and at constant acceleration. The error is at the
coil's centre, 113 mm from the head frame's origin along its z axis, as in the prediction study.
What is left at constant velocity is the trace's own unpredictability over the horizon: no
filter fed only the past removes it. Nothing here is a test.
"""

import argparse
import csv

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.spatial.transform import Rotation

COIL = np.array([0.0, 0.0, 0.113])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trace")
    ap.add_argument("--horizons-ms", default="30,58")
    ap.add_argument("--skip-s", type=float, default=2.5, help="leave out the start, s")
    a = ap.parse_args()
    with open(a.trace) as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    col = {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}
    t = col["t_s"]
    pos = PchipInterpolator(t, np.stack([col["x_mm"], col["y_mm"], col["z_mm"]], -1) / 1e3)
    quat = np.stack([col["qx"], col["qy"], col["qz"], col["qw"]], -1)
    rotvec = PchipInterpolator(t, Rotation.from_quat(quat).as_rotvec())

    def coil(tq):
        return Rotation.from_rotvec(rotvec(tq)).apply(COIL) + pos(tq)

    ts = np.arange(t[0] + a.skip_s, t[-1] - 0.2, 1 / 500)
    # The derivatives from the past only (a causal view of the true state).
    e = 1e-4
    x0, x1, x2 = coil(ts), coil(ts - e), coil(ts - 2 * e)
    v = (x0 - x1) / e
    acc = (x0 - 2 * x1 + x2) / e**2
    print("| horizon | hold the pose: RMS / max (mm) | constant velocity | constant acceleration |")
    print("|---|---|---|---|")
    for h_ms in (float(x) for x in a.horizons_ms.split(",")):
        h = h_ms / 1e3
        truth = coil(ts + h)
        cells = []
        for pred in (x0, x0 + v * h, x0 + v * h + acc * h * h / 2):
            err = np.linalg.norm(pred - truth, axis=1) * 1e3
            cells.append(f"{np.sqrt(np.mean(err**2)):.3f} / {err.max():.2f}")
        print(f"| {h_ms:g} ms | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
