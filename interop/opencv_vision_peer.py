"""Expose OpenCV's connectedComponentsWithStats, projectPoints and undistortPointsIter to mocomp's
tests: JSON lines on stdin/stdout.

Requests:
  {"op": "version"} -> {"version": "4.14.0"}
  {"op": "components", "width": w, "height": h, "mask": "0101..."}  (row-major, '1' = foreground)
    -> {"count": n, "stats": [[left, top, width, height, area], ...], "centroids": [[x, y], ...]}
Labels are 8-connected; the background label 0 is left out.
  {"op": "project", "k": [fx, fy, cx, cy], "d": [k1, k2, p1, p2, k3, k4, k5, k6],
   "points": [[x, y, z], ...]} -> {"pixels": [[u, v], ...]}   (cv2.projectPoints, no rotation)
  {"op": "undistort", "k": [...], "d": [...], "pixels": [[u, v], ...]}
    -> {"normalised": [[x, y], ...]}   (cv2.undistortPointsIter, to 1e-15 or 200 iterations)
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
    if op in ("project", "undistort"):
        fx, fy, cx, cy = req["k"]
        k = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        d = np.array(req["d"], dtype=np.float64)
        if op == "project":
            pts = np.array(req["points"], dtype=np.float64).reshape(-1, 1, 3)
            px, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k, d)
            return {"pixels": px.reshape(-1, 2).tolist()}
        px = np.array(req["pixels"], dtype=np.float64).reshape(-1, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
        n = cv2.undistortPointsIter(px, k, d, None, None, criteria)
        return {"normalised": n.reshape(-1, 2).tolist()}
    return {"error": f"unknown op {op!r}"}


if __name__ == "__main__":
    serve(handle)
