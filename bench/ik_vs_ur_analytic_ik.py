#!/usr/bin/env python3
"""IK and FK throughput: mocomp (native Rust) against ur-analytic-ik (C++, timed through its
Python API), on the same seeded poses, in the same run.

    .venv/bin/python bench/ik_vs_ur_analytic_ik.py [--model ur5e] [--poses 2000] [--rounds 15]

Prints the median time per call over the rounds, calls per second, and the ratio. The peer is
measured through its Python bindings (numpy in, list of numpy arrays out), which is how Python
users call it, so its figure includes the binding cost; its native C++ time (8.6 µs per IK,
0.44 µs per FK, reported in ../shared/reference/peers.md) is printed for comparison.

With --callgrind, our IK is also run under valgrind's callgrind and its instructions per solve
are printed: a figure that does not drift with machine load.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import re

import numpy as np
import ur_analytic_ik

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def time_rounds(fn, items, rounds):
    per_call = []
    for _ in range(rounds):
        t0 = time.perf_counter_ns()
        for it in items:
            fn(it)
        per_call.append((time.perf_counter_ns() - t0) / len(items))
    return statistics.median(per_call)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", default="ur5e")
    ap.add_argument("--poses", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--seed", type=int, default=20261123)
    ap.add_argument("--callgrind", action="store_true", help="also count instructions per IK")
    args = ap.parse_args()

    peer = getattr(ur_analytic_ik, args.model)
    rng = np.random.default_rng(args.seed)
    joints = rng.uniform(-np.pi, np.pi, size=(args.poses, 6))
    poses = [np.ascontiguousarray(peer.forward_kinematics(*q)) for q in joints]

    # Ours: a release build of the timing example, on the same poses.
    subprocess.run(
        ["cargo", "build", "--quiet", "--release", "-p", "mocomp-kin", "--example", "ik_throughput"],
        cwd=ROOT,
        check=True,
    )
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False) as f:
        json.dump({"joints": joints.tolist(), "poses": [p.tolist() for p in poses]}, f)
        path = f.name
    exe = os.path.join(ROOT, "target/release/examples/ik_throughput")
    instructions = None
    try:
        out = subprocess.run(
            [exe, args.model, path, str(args.rounds)], check=True, capture_output=True, text=True
        ).stdout
        if args.callgrind:
            with tempfile.TemporaryDirectory() as d:
                cg = subprocess.run(
                    ["valgrind", "--tool=callgrind", f"--callgrind-out-file={d}/cg.out",
                     "--toggle-collect=*Arm*ik*", exe, args.model, path, "1"],
                    check=True, capture_output=True, text=True,
                ).stderr
            m = re.search(r"Collected : (\d+)", cg)
            instructions = int(m.group(1)) / args.poses if m else None
    finally:
        os.unlink(path)
    ours = json.loads(out)

    # The peer through Python. Its C++ prints warnings to stdout at its known defects; silence fd 1.
    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        peer_ik = time_rounds(peer.inverse_kinematics, poses, args.rounds)
        peer_fk = time_rounds(lambda q: peer.forward_kinematics(*q), [tuple(q) for q in joints], args.rounds)
        peer_solutions = sum(len(peer.inverse_kinematics(p)) for p in poses)
    finally:
        os.dup2(saved, 1)
        os.close(devnull)

    def row(name, ns):
        return f"{name:<44} {ns / 1000:>9.3f} µs {1e9 / ns:>14,.0f} /s"

    print(f"model {args.model}, {args.poses} seeded poses (seed {args.seed}), median of {args.rounds} rounds")
    print(row("mocomp IK, all solutions (Rust, native)", ours["ik_ns_median"]))
    print(row("ur-analytic-ik IK, all solutions (Python API)", peer_ik))
    print(row("mocomp FK (Rust, native)", ours["fk_ns_median"]))
    print(row("ur-analytic-ik FK (Python API)", peer_fk))
    print(f"IK speed ratio (peer via Python / ours): {peer_ik / ours['ik_ns_median']:.1f}x; "
          f"FK: {peer_fk / ours['fk_ns_median']:.1f}x")
    print(f"against the peer's native C++ figures from peers.md (8.6 µs IK, 0.44 µs FK): "
          f"{8600 / ours['ik_ns_median']:.1f}x and {440 / ours['fk_ns_median']:.1f}x")
    if instructions is not None:
        print(f"mocomp IK under callgrind: {instructions:,.0f} instructions per all-solution solve")
    print(f"solutions found: mocomp {ours['solutions_per_round']}, ur-analytic-ik {peer_solutions}")


if __name__ == "__main__":
    main()
