"""The issue-33 table: each run with the paper's pipeline, mocomp and the oracle, the excess over
the oracle and the split of the error into the prediction's and the execution's share.

    cargo build --release --bin mocomp
    python3 bench/oracle_table.py [--bin target/release/mocomp] [--out /tmp/oracle-table]

Runs `mocomp demo --controllers paper,mocomp,oracle --json` with each row's options and prints
one Markdown table. The experiment is deterministic: the same binary gives the same table.
Nothing here is a test.
"""

import argparse
import json
import os
import subprocess

RUNS = [
    ("default", []),
    ("nods", ["--motion", "nods"]),
    ("nods-dropouts", ["--motion", "nods", "--tracker-dropouts-per-s", "0.5"]),
    ("demo-nods", ["--config", "examples/demo-nods.toml"]),
    ("irregular", ["--motion-file", "examples/head-irregular-60s.csv", "--seconds", "60"]),
]


def f(x):
    return "–" if x is None else f"{x:.3f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default="target/release/mocomp")
    ap.add_argument("--out", default="/tmp/oracle-table")
    a = ap.parse_args()
    print("| run | controller | d RMS | d max | translation RMS (mm) | excess d RMS | excess d max "
          "| prediction's share RMS (mm) | execution's share RMS (mm) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, opts in RUNS:
        out = subprocess.run(
            [a.bin, "demo", "--controllers", "paper,mocomp,oracle", "--json", "--quiet",
             "--out", os.path.join(a.out, name)] + opts,
            capture_output=True, text=True, check=True)
        j = json.loads(out.stdout)
        for r in j["controllers"]:
            ex = r.get("excess_over_oracle") or {}
            share = lambda k: (r.get(k) or {}).get("rms")
            print(f"| {name} | {r['controller']} | {r['d_rms']:.3f} | {r['d_max']:.3f} "
                  f"| {r['translation_mm_rms']:.3f} | {f(ex.get('d_rms'))} | {f(ex.get('d_max'))} "
                  f"| {f(share('prediction_mm'))} | {f(share('execution_mm'))} |")
        if j.get("head_robot_lags"):
            print(f"| {name} | head robot lagged {j['head_robot_lagged_s']:.2f} s in "
                  f"{len(j['head_robot_lags'])} intervals | | | | | | | |")


if __name__ == "__main__":
    main()
