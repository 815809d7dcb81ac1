"""Expose the PyPI package ur-analytic-ik to mocomp's tests: JSON lines on stdin/stdout.

Requests (one per line):
  {"op": "version"}                                   -> {"version": "..."}
  {"op": "fk", "model": "ur5e", "joints": [[q1..q6], ...]}  -> {"fk": [[[4x4 rows]], ...]}
  {"op": "ik", "model": "ur5e", "poses": [[[4x4 rows]], ...]} -> {"ik": [[[q1..q6], ...], ...]}
  {"op": "ik_closest", "model": ..., "poses": [...], "current": [[q1..q6], ...]}
                                                      -> {"ik_closest": [[[q1..q6]], ...]}
Errors answer {"error": "..."} and the helper keeps running.

The peer's C++ code prints warnings ("Detected and filtered incorrect IK solution") to the process's
stdout, so the loop captures fd 1 (jsonlines.serve) and each answer carries "peer_warnings": the
warning lines the peer printed while serving that request.
"""

from importlib import metadata

import numpy as np
import ur_analytic_ik
from jsonlines import serve


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": metadata.version("ur-analytic-ik")}
    model = getattr(ur_analytic_ik, req["model"])
    if op == "fk":
        return {"fk": [model.forward_kinematics(*q).tolist() for q in req["joints"]]}
    if op == "ik":
        out = []
        for rows in req["poses"]:
            t = np.ascontiguousarray(np.array(rows, dtype=np.float64))
            out.append([s.tolist() for s in model.inverse_kinematics(t)])
        return {"ik": out}
    if op == "ik_closest":
        out = []
        for rows, q in zip(req["poses"], req["current"]):
            t = np.ascontiguousarray(np.array(rows, dtype=np.float64))
            out.append([s.tolist() for s in model.inverse_kinematics_closest(t, *q)])
        return {"ik_closest": out}
    return {"error": f"unknown op {op!r}"}


def main():
    serve(handle, capture_stdout=True)


if __name__ == "__main__":
    main()
