"""Expose the MRI's third-party peers to mocomp's tests: JSON lines on stdin/stdout.

scikit-image's marching cubes is the peer isosurface of the scalp mocomp segments from a T1;
nibabel writes the T1 back in the other ways NIfTI allows (qform only, a left-handed voxel
grid, scaled integers, NaN, metres, uncompressed); MNE ships fsaverage's inner skull, the brain's
envelope the scalp must enclose.

Requests (one per line):
  {"op": "version"} -> {"version": "scikit-image X, nibabel Y, mne Z"}
  {"op": "marching_cubes", "mask": P, "dims": [nx, ny, nz], "ras_from_voxel_mm": 4x4}
      P holds one byte a voxel (i fastest, 1 inside): marching cubes at 0.5 on the mask padded by
      one voxel of outside, carried to RAS millimetres
      -> {"vertices_mm": [[x, y, z], ...], "triangles": [[a, b, c], ...]}
  {"op": "inner_skull"} -> {"vertices_mm": [[x, y, z], ...]}: fsaverage's inner skull (MRI frame)
  {"op": "resave", "src": P, "dst": Q, "variant": V}
      writes the NIfTI P again as Q (".nii" or ".nii.gz"), V one of
        qform_rotated: the same voxels, the sform dropped, a qform of the old affine turned 20°
          about (1, 2, 3) and moved (5, -7, 11) mm;
        las: the voxels mirrored along i with an affine that keeps every voxel where it was;
        int16_scaled: stored as int16 = (value - 10) / 0.5 with scl_slope 0.5, scl_inter 10;
        float32_nan: float32, with a corner block of NaN;
        metres: the affine in metres, xyzt_units metres;
        plain: as read, uncompressed when Q ends in .nii
      -> {"written": Q, "ras_from_voxel": 4x4 as nibabel reads it back}
Errors answer {"error": "..."} and the helper keeps running.
"""

import gzip
import os
from importlib import metadata

import mne
import nibabel as nib
import numpy as np
from jsonlines import serve
from skimage.measure import marching_cubes


def mc(req):
    dims = [int(d) for d in req["dims"]]
    mask = np.fromfile(req["mask"], dtype=np.uint8)
    mask = mask.reshape(dims[::-1]).transpose(2, 1, 0)
    v, f, _, _ = marching_cubes(np.pad(mask, 1).astype(np.float32), 0.5)
    v = v - 1.0
    a = np.asarray(req["ras_from_voxel_mm"], dtype=np.float64)
    ras = v @ a[:3, :3].T + a[:3, 3]
    return {"vertices_mm": ras.tolist(), "triangles": f.tolist()}


def inner_skull():
    path = os.path.join(os.path.dirname(mne.__file__), "data", "fsaverage",
                        "fsaverage-inner_skull-bem.fif")
    surf = mne.read_bem_surfaces(path, verbose="error")[0]
    return {"vertices_mm": (np.asarray(surf["rr"]) * 1000.0).tolist()}


def rotation(deg, axis):
    axis = np.asarray(axis, dtype=np.float64)
    axis /= np.linalg.norm(axis)
    t = np.radians(deg)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * k @ k


def resave(req):
    img = nib.load(req["src"])
    data = np.asarray(img.dataobj.get_unscaled())
    aff = img.affine.copy()
    variant = req["variant"]
    if variant == "qform_rotated":
        m = np.eye(4)
        m[:3, :3] = rotation(20.0, [1, 2, 3])
        m[:3, 3] = [5.0, -7.0, 11.0]
        out = nib.Nifti1Image(data, None)
        out.set_qform(m @ aff, code=1)
        out.set_sform(None, code=0)
    elif variant == "las":
        flip = np.eye(4)
        flip[0, 0] = -1.0
        flip[0, 3] = data.shape[0] - 1
        out = nib.Nifti1Image(np.ascontiguousarray(data[::-1]), aff @ flip)
        out.set_qform(aff @ flip, code=1)
    elif variant == "int16_scaled":
        stored = np.round((data.astype(np.float64) - 10.0) / 0.5).astype(np.int16)
        out = nib.Nifti1Image(stored, aff)
    elif variant == "float32_nan":
        f = data.astype(np.float32)
        f[:8, :8, -8:] = np.nan
        out = nib.Nifti1Image(f, aff)
    elif variant == "metres":
        m = aff.copy()
        m[:3, :] /= 1000.0
        out = nib.Nifti1Image(data, m)
        out.set_data_dtype(data.dtype)
        out.header.set_xyzt_units("meter")
        nib.save(out, req["dst"])
        return {"written": req["dst"], "ras_from_voxel": nib.load(req["dst"]).affine.tolist()}
    elif variant == "plain":
        out = nib.Nifti1Image(data, aff)
    else:
        return {"error": f"unknown variant {variant!r}"}
    out.header.set_xyzt_units("mm")
    out.set_data_dtype(np.asarray(out.dataobj).dtype)
    if variant != "int16_scaled":
        nib.save(out, req["dst"])
    else:
        # nibabel chooses its own scaling on save: write the integers unscaled, then set
        # scl_slope and scl_inter (bytes 112 and 116 of the NIfTI-1 header) to what they mean.
        plain = req["dst"][:-3] if req["dst"].endswith(".gz") else req["dst"]
        nib.save(out, plain)
        with open(plain, "r+b") as fh:
            fh.seek(112)
            fh.write(np.array([0.5, 10.0], dtype="<f4").tobytes())
        if plain != req["dst"]:
            with open(plain, "rb") as fi, gzip.open(req["dst"], "wb") as fo:
                fo.write(fi.read())
            os.remove(plain)
    return {"written": req["dst"], "ras_from_voxel": nib.load(req["dst"]).affine.tolist()}


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": ", ".join(
            f"{p} {metadata.version(p)}" for p in ("scikit-image", "nibabel", "mne"))}
    if op == "marching_cubes":
        return mc(req)
    if op == "inner_skull":
        return inner_skull()
    if op == "resave":
        return resave(req)
    return {"error": f"unknown op {op!r}"}


def main():
    serve(handle)


if __name__ == "__main__":
    main()
