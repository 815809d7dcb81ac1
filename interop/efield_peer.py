"""Expose MNE-Python's sphere-model magnetic field (Sarvas 1987) to mocomp's tests as an
independent peer for the TMS coil's electric field: JSON lines on stdin/stdout.

By reciprocity, the E-field a coil induces at a point r inside a conducting sphere, along a
unit direction p, is E(r)·p = -dI/dt * sum_i m_i . B_p(r_i): B_p is the magnetic field outside
the sphere of a unit current dipole p at r, evaluated at each of the coil's magnetic dipoles r_i
with moment m_i (A m^2 per A). MNE computes B_p for MEG sensors; here each coil dipole is one
"integration point" of a single sensor (its position, its moment's direction as the point's
normal, the moment's size as its weight), so MNE's sum is the coil's sum.

The function used is MNE's own (mne.forward._compute_forward_numba._do_sphere_field, the one its
forward model uses for spherical heads); mne is pinned in requirements-interop.txt.

Requests (one per line):
  {"op": "version"} -> {"version": "mne X"}
  {"op": "efield", "sphere_centre_m": [x, y, z], "dipoles_m": [[x, y, z], ...],
   "moments": [[mx, my, mz], ...], "didt": A_PER_S, "points_m": [[x, y, z], ...]}
      dipoles and moments already placed in the head frame
      -> {"E_V_per_m": [[ex, ey, ez], ...]}
Errors answer {"error": "..."} and the helper keeps running.
"""

from importlib import metadata

import numpy as np
from jsonlines import serve
from mne.forward._compute_forward_numba import _do_sphere_field


def efield(req):
    centre = np.asarray(req["sphere_centre_m"], dtype=np.float64)
    rmags = np.asarray(req["dipoles_m"], dtype=np.float64)
    moments = np.asarray(req["moments"], dtype=np.float64)
    points = np.atleast_2d(np.asarray(req["points_m"], dtype=np.float64))
    ws = np.linalg.norm(moments, axis=1)
    keep = ws > 0
    cosmags = np.zeros_like(moments)
    cosmags[keep] = moments[keep] / ws[keep, None]
    bins = np.zeros(len(rmags), dtype=np.int64)
    # Rows 3k + j: the field of a unit current dipole along axis j at point k, summed over the
    # coil's dipoles as m_i . B(r_i).
    b = _do_sphere_field(points, rmags, cosmags, ws, bins, centre)
    e = -float(req["didt"]) * b[:, 0].reshape(len(points), 3)
    return {"E_V_per_m": e.tolist()}


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": f"mne {metadata.version('mne')}"}
    if op == "efield":
        return efield(req)
    raise ValueError(f"unknown op {op!r}")


if __name__ == "__main__":
    serve(handle)
