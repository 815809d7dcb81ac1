"""Expose OpenCV's calibrateRobotWorldHandEye to mocomp's tests: JSON lines on stdin/stdout.

Requests (one per line):
  {"op": "version"} -> {"version": "4.14.0"}
  {"op": "calibrate", "method": "SHAH" | "LI",
   "sets": [{"base_from_flange": [[4x4 rows], ...], "tracker_from_marker": [[4x4 rows], ...]}, ...]}
    -> {"results": [{"X": [[4x4]], "Y": [[4x4]], "seconds": t}, ...]}
X = flange_from_marker, Y = base_from_tracker, metres. OpenCV solves A X = Z B with
A = cTw (world->camera), B = gTb (base->gripper); the mapping (from peers.md, checked by the
noise-free interop test):
  R_world2cam = inverse(tracker_from_marker_i), R_base2gripper = inverse(base_from_flange_i),
  Y = inverse(base2world), X = inverse(gripper2cam).
"seconds" times the OpenCV call alone (median of `repeat` calls, default 1).
"""

import statistics
import time

import cv2
import numpy as np
from jsonlines import serve

METHODS = {
    "SHAH": cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    "LI": cv2.CALIB_ROBOT_WORLD_HAND_EYE_LI,
}


def inv(t):
    r, p = t[:3, :3], t[:3, 3]
    out = np.eye(4)
    out[:3, :3] = r.T
    out[:3, 3] = -r.T @ p
    return out


def calibrate(method, set_, repeat):
    m = [np.array(t, dtype=np.float64) for t in set_["base_from_flange"]]
    n = [np.array(t, dtype=np.float64) for t in set_["tracker_from_marker"]]
    w2c = [inv(t) for t in n]
    b2g = [inv(t) for t in m]
    args = (
        [t[:3, :3].copy() for t in w2c],
        [t[:3, 3].reshape(3, 1).copy() for t in w2c],
        [t[:3, :3].copy() for t in b2g],
        [t[:3, 3].reshape(3, 1).copy() for t in b2g],
    )
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r_b2w, t_b2w, r_g2c, t_g2c = cv2.calibrateRobotWorldHandEye(*args, method=METHODS[method])
        times.append(time.perf_counter() - t0)
    b2w = np.eye(4)
    b2w[:3, :3], b2w[:3, 3] = r_b2w, t_b2w.ravel()
    g2c = np.eye(4)
    g2c[:3, :3], g2c[:3, 3] = r_g2c, t_g2c.ravel()
    return {"X": inv(g2c).tolist(), "Y": inv(b2w).tolist(), "seconds": statistics.median(times)}


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": cv2.__version__}
    if op == "calibrate":
        repeat = int(req.get("repeat", 1))
        return {"results": [calibrate(req["method"], s, repeat) for s in req["sets"]]}
    return {"error": f"unknown op {op!r}"}


def main():
    serve(handle)


if __name__ == "__main__":
    main()
