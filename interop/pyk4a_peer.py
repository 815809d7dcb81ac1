"""Play an Azure Kinect recording with pyk4a (the PyPI wheel pyk4a-bundle, the SDK's own libk4a and
libk4arecord 1.4.2) for mocomp's tests: JSON lines on stdin/stdout.

Requests:
  {"op": "version"} -> {"version": "1.5.0"}  (pyk4a-bundle)
  {"op": "read", "path": p} -> {
      "configuration": {"depth_mode": n, "camera_fps": n, "ir_track_enabled": b, ...},
      "length_usec": n,
      "depth_camera": {"matrix": [[...]], "distortion": [k1, k2, p1, p2, k3, k4, k5, k6]},
      "captures": [{"ir": {"shape": [h, w], "timestamp_usec": n, "sum": n, "weighted": n},
                    "depth": {...}}, ...]}
  "sum" is the pixels' sum and "weighted" sum(pixel * (index + 1)) mod 2^64: two checksums
  that change when any pixel does. An image the capture lacks is null.
"""

from importlib import metadata as md

import numpy as np
from pyk4a import CalibrationType, PyK4APlayback

from jsonlines import serve


def image(pixels, timestamp):
    if pixels is None:
        return None
    flat = pixels.astype(np.uint64).ravel()
    with np.errstate(over="ignore"):
        weighted = int(np.sum(flat * (np.arange(flat.size, dtype=np.uint64) + np.uint64(1)),
                              dtype=np.uint64))
    return {"shape": list(pixels.shape), "timestamp_usec": int(timestamp),
            "sum": int(flat.sum(dtype=np.uint64)), "weighted": weighted}


def read(path):
    p = PyK4APlayback(path)
    p.open()
    try:
        cfg = {k: (int(v) if not isinstance(v, bool) else v) for k, v in p.configuration.items()}
        cal = p.calibration
        depth_camera = {
            "matrix": cal.get_camera_matrix(CalibrationType.DEPTH).tolist(),
            "distortion": cal.get_distortion_coefficients(CalibrationType.DEPTH).tolist(),
        }
        captures = []
        while True:
            try:
                c = p.get_next_capture()
            except EOFError:
                break
            captures.append({"ir": image(c.ir, c.ir_timestamp_usec),
                             "depth": image(c.depth, c.depth_timestamp_usec)})
        return {"configuration": cfg, "length_usec": int(p.length),
                "depth_camera": depth_camera, "captures": captures}
    finally:
        p.close()


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": md.version("pyk4a-bundle")}
    if op == "read":
        return read(req["path"])
    return {"error": f"unknown op {op!r}"}


if __name__ == "__main__":
    serve(handle)
