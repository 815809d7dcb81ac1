"""Expose the head's third-party writers to mocomp's tests: JSON lines on stdin/stdout.

MNE-Python ships FreeSurfer's fsaverage head (a BEM scalp, MRI frame, metres); trimesh writes it
as STL, PLY and OBJ, nibabel as GIfTI and as a FreeSurfer surface. mocomp reads each file back.

Requests (one per line):
  {"op": "version"} -> {"version": "mne X, nibabel Y, trimesh Z"}
  {"op": "fsaverage_head"} -> {"vertices_m": [[x, y, z], ...], "triangles": [[a, b, c], ...]}
  {"op": "write", "format": F, "path": P, "scale": S, "encoding": E}
      writes the fsaverage head, its coordinates times S (1000: millimetres), to P:
      F = stl | stl_ascii | ply | ply_ascii | obj (trimesh), gii (nibabel; E = GIFTI_ENCODING_B64GZ,
      GIFTI_ENCODING_B64BIN or GIFTI_ENCODING_ASCII), fs (nibabel's write_geometry, with a volume
      geometry whose c_ras is (1, -2, 3) mm) -> {"written": P, "vertices": [[x, y, z], ...]}: the
      coordinates as the format stores them (float32 where it stores float32).
  {"op": "fsaverage_points", "montage": M} -> {"fiducials_m": {"nasion": [x, y, z], "lpa": ...,
      "rpa": ...}, "eeg_m": {"F3": [x, y, z], ...}}: MNE's fsaverage fiducials
      (fsaverage-fiducials.fif) and the positions of its montage M (fsaverage_1020, _1010 or _1005,
      read from MNE's TSV as shipped), the head's frame, metres.
Errors answer {"error": "..."} and the helper keeps running.
"""

import os
from importlib import metadata

import mne
import nibabel as nib
import numpy as np
import trimesh
from jsonlines import serve


def head():
    path = os.path.join(os.path.dirname(mne.__file__), "data", "fsaverage", "fsaverage-head.fif")
    surf = mne.read_bem_surfaces(path, verbose="error")[0]
    return np.asarray(surf["rr"], dtype=np.float64), np.asarray(surf["tris"], dtype=np.int64)


def write(req):
    v, f = head()
    v = v * float(req.get("scale", 1.0))
    fmt, path = req["format"], req["path"]
    stored = v
    if fmt in ("stl", "stl_ascii", "ply", "ply_ascii", "obj"):
        mesh = trimesh.Trimesh(v, f, process=False)
        if fmt == "stl":
            mesh.export(path, file_type="stl")
            stored = v.astype(np.float32).astype(np.float64)
        elif fmt == "stl_ascii":
            mesh.export(path, file_type="stl_ascii")
        elif fmt == "ply":
            mesh.export(path, file_type="ply", encoding="binary")
            stored = v.astype(np.float32).astype(np.float64)
        elif fmt == "ply_ascii":
            mesh.export(path, file_type="ply", encoding="ascii")
        else:
            mesh.export(path, file_type="obj")
    elif fmt == "gii":
        enc = req.get("encoding", "GIFTI_ENCODING_B64GZ")
        pts = nib.gifti.GiftiDataArray(
            v.astype(np.float32), intent="NIFTI_INTENT_POINTSET", datatype="NIFTI_TYPE_FLOAT32",
            encoding=enc)
        tri = nib.gifti.GiftiDataArray(
            f.astype(np.int32), intent="NIFTI_INTENT_TRIANGLE", datatype="NIFTI_TYPE_INT32",
            encoding=enc)
        nib.save(nib.gifti.GiftiImage(darrays=[pts, tri]), path)
        stored = v.astype(np.float32).astype(np.float64)
    elif fmt == "fs":
        info = {
            "head": np.array([2, 0, 20], dtype=np.int32), "valid": "1  # volume info valid",
            "filename": "T1.mgz", "volume": np.array([256, 256, 256]),
            "voxelsize": np.array([1.0, 1.0, 1.0]), "xras": np.array([-1.0, 0.0, 0.0]),
            "yras": np.array([0.0, 0.0, -1.0]), "zras": np.array([0.0, 1.0, 0.0]),
            "cras": np.array([1.0, -2.0, 3.0]),
        }
        nib.freesurfer.io.write_geometry(path, v, f.astype(np.int32), volume_info=info)
        stored = v.astype(np.float32).astype(np.float64)
    else:
        return {"error": f"unknown format {fmt!r}"}
    # Read back what the writer wrote, where the format stores text (its own rounding).
    if fmt in ("stl_ascii", "ply_ascii", "obj"):
        back = trimesh.load(path, process=False, force="mesh")
        stored = np.asarray(back.vertices, dtype=np.float64)
    return {"written": path, "vertices": stored.tolist()}


def points(req):
    data = os.path.join(os.path.dirname(mne.__file__), "data", "fsaverage", "fsaverage-fiducials.fif")
    pts, _frame = mne.io.read_fiducials(data)
    names = {1: "lpa", 2: "nasion", 3: "rpa"}
    fiducials = {names[int(p["ident"])]: [float(x) for x in p["r"]] for p in pts}
    montage = req.get("montage", "fsaverage_1020")
    if montage not in ("fsaverage_1020", "fsaverage_1010", "fsaverage_1005"):
        return {"error": f"unknown montage {montage!r}"}
    tsv = os.path.join(os.path.dirname(mne.__file__), "channels", "data", "montages", montage + ".tsv")
    eeg = {}
    with open(tsv) as f:
        next(f)
        for line in f:
            label, x, y, z = line.split()
            eeg[label] = [float(x), float(y), float(z)]
    return {"fiducials_m": fiducials, "eeg_m": eeg}


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": ", ".join(
            f"{p} {metadata.version(p)}" for p in ("mne", "nibabel", "trimesh"))}
    if op == "fsaverage_head":
        v, f = head()
        return {"vertices_m": v.tolist(), "triangles": f.tolist()}
    if op == "write":
        return write(req)
    if op == "fsaverage_points":
        return points(req)
    return {"error": f"unknown op {op!r}"}


def main():
    serve(handle)


if __name__ == "__main__":
    main()
