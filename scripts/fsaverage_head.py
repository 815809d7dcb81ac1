#!/usr/bin/env python3
"""Writes FreeSurfer's fsaverage head (the BEM scalp MNE-Python ships, MRI frame) as binary PLY
in millimetres: a real head to run mocomp on (`[head] mesh`, `units = "mm"`).

    .venv/bin/python scripts/fsaverage_head.py OUT.ply

The surface is FreeSurfer's (its licence: https://surfer.nmr.mgh.harvard.edu/fswiki/FreeSurferSoftwareLicense),
as distributed with MNE-Python (BSD-3-Clause); nothing here changes it but the unit.
"""

import os
import sys

import mne
import numpy as np
import trimesh


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: fsaverage_head.py OUT.ply")
    path = os.path.join(os.path.dirname(mne.__file__), "data", "fsaverage", "fsaverage-head.fif")
    surf = mne.read_bem_surfaces(path, verbose="error")[0]
    v = np.asarray(surf["rr"], dtype=np.float64) * 1000.0
    f = np.asarray(surf["tris"], dtype=np.int64)
    trimesh.Trimesh(v, f, process=False).export(sys.argv[1], file_type="ply")
    lo, hi = v.min(axis=0), v.max(axis=0)
    print(f"wrote {sys.argv[1]}: {len(v)} vertices, {len(f)} triangles, "
          f"box {lo.round(1).tolist()} to {hi.round(1).tolist()} mm")


if __name__ == "__main__":
    main()
