#!/usr/bin/env python3
"""Hand-eye / robot-world calibration accuracy and speed: mocomp (li, shah, refined) against
OpenCV's calibrateRobotWorldHandEye (SHAH, LI) on the same seeded synthetic sets.

    .venv/bin/python bench/handeye_vs_opencv.py [--counts 10,20,50,200] [--trials 40]

Sets: tracker noise 0.1 mm / 0.1°, robot noise 0.03 mm / 0.01° (per axis), rotations 15°-40°
about random axes, shifts of ±20 cm (mocomp_calib::synth defaults). For each N and method it
prints the median and 95th percentile of the rotation (deg) and translation (mm) errors of X and Y
and the median solve time. Our times are of the whole solve (checks, closed forms, refinement,
outlier analysis, uncertainty) in a release build; OpenCV's are of its C++ call alone, through
Python.
"""

import argparse
import json
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "interop"))
import opencv_handeye_peer as ocv  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def rot_err_deg(a, b):
    r = np.array(a)[:3, :3].T @ np.array(b)[:3, :3]
    c = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(c)))


def trans_err_mm(a, b):
    return float(np.linalg.norm(np.array(a)[:3, 3] - np.array(b)[:3, 3]) * 1000.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--counts", default="10,20,50,200")
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--repeat", type=int, default=3, help="timing repeats per solve")
    ap.add_argument("--seed", type=int, default=1_000_000, help="set t of size N uses seed + 10000 N + t")
    args = ap.parse_args()

    subprocess.run(
        ["cargo", "build", "--quiet", "--release", "-p", "mocomp-calib", "--example", "calib_bench"],
        cwd=ROOT,
        check=True,
    )
    exe = os.path.join(ROOT, "target/release/examples/calib_bench")
    out = subprocess.run(
        [exe, args.counts, str(args.trials), str(args.repeat), str(args.seed)], check=True, capture_output=True, text=True
    ).stdout
    cases = json.loads(out)["cases"]

    methods = ["li", "shah", "refined", "OpenCV SHAH", "OpenCV LI"]
    rows = {}
    for case in cases:
        n = case["count"]
        results = dict(case["ours"])
        for m in ("SHAH", "LI"):
            results["OpenCV " + m] = ocv.calibrate(m, case["pairs"], args.repeat)
        for m in methods:
            r = results[m]
            e = rows.setdefault((n, m), {"xr": [], "xt": [], "yr": [], "yt": [], "s": []})
            e["xr"].append(rot_err_deg(r["X"], case["truth"]["X"]))
            e["xt"].append(trans_err_mm(r["X"], case["truth"]["X"]))
            e["yr"].append(rot_err_deg(r["Y"], case["truth"]["Y"]))
            e["yt"].append(trans_err_mm(r["Y"], case["truth"]["Y"]))
            e["s"].append(r["seconds"])

    def q(v, p):
        return float(np.percentile(v, p))

    print(f"{args.trials} trials per N (seed {args.seed}); errors as median / p95; time = median solve")
    header = f"{'N':>4} {'method':<12} {'X rot deg':>15} {'X trans mm':>15} {'Y rot deg':>15} {'Y trans mm':>15} {'time ms':>9}"
    print(header)
    print("-" * len(header))
    for n in sorted({c["count"] for c in cases}):
        for m in methods:
            e = rows[(n, m)]
            cells = [f"{q(e[k], 50):>6.3f} / {q(e[k], 95):>6.3f}" for k in ("xr", "xt", "yr", "yt")]
            print(f"{n:>4} {m:<12} {cells[0]:>15} {cells[1]:>15} {cells[2]:>15} {cells[3]:>15} {q(e['s'], 50) * 1e3:>9.3f}")
        best = min(q(rows[(n, m)]["yt"], 50) for m in ("OpenCV SHAH", "OpenCV LI"))
        ours = q(rows[(n, "refined")]["yt"], 50)
        print(f"{n:>4} refined vs OpenCV's better method on Y translation (median): {best / ours:.1f}x more accurate")
        print()


if __name__ == "__main__":
    main()
