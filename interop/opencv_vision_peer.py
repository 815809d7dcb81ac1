"""Expose OpenCV's connectedComponentsWithStats to mocomp's tests: JSON lines on stdin/stdout.

Requests:
  {"op": "version"} -> {"version": "4.14.0"}
  {"op": "components", "width": w, "height": h, "mask": "0101..."}  (row-major, '1' = foreground)
    -> {"count": n, "stats": [[left, top, width, height, area], ...], "centroids": [[x, y], ...]}
Labels are 8-connected; the background label 0 is left out.
"""

import cv2
import numpy as np
from jsonlines import serve


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": cv2.__version__}
    if op == "components":
        w, h = int(req["width"]), int(req["height"])
        mask = (np.frombuffer(req["mask"].encode("ascii"), dtype=np.uint8) - ord("0")).reshape(h, w)
        n, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        return {"count": int(n - 1), "stats": stats[1:].tolist(), "centroids": centroids[1:].tolist()}
    return {"error": f"unknown op {op!r}"}


if __name__ == "__main__":
    serve(handle)
