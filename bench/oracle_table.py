"""The issue-33 table: each run with the paper's pipeline, mocomp and the oracle, the excess over
the oracle and the split of the error into the prediction's and the execution's share.

    cargo build --release --bin mocomp
    python3 bench/oracle_table.py [--bin target/release/mocomp] [--out /tmp/oracle-table]

Runs `mocomp demo --controllers paper,mocomp,oracle --json` with each row's options and prints
one Markdown table. The experiment is deterministic: the same binary gives the same table.
With `--before`, each row also runs with the settings issue 33 started from (no learned
prediction, 25 rad/s², half of each joint's speed, servoj gain 1500, no setpoint lead and the
filter's angular acceleration bound at 50 rad/s²), merged into the row's
configuration, so one binary shows both in one run. Code changes are not undone: the before rows
follow the goal's speed along the prediction (since 150bb87), as the after rows do. Nothing here is a test.
"""

import argparse
import json
import os
import re
import subprocess

RUNS = [
    ("default", []),
    ("nods", ["--motion", "nods"]),
    ("nods-dropouts", ["--motion", "nods", "--tracker-dropouts-per-s", "0.5"]),
    ("demo-nods", ["--config", "examples/demo-nods.toml"]),
    ("irregular", ["--motion-file", "examples/head-irregular-60s.csv", "--seconds", "60"]),
]


# What issue 33 changed, as the lines of the printed configuration that say it.
BEFORE = {
    "learned": "false",
    "max_joint_accel_rad_s2": "25.0",
    "speed_fraction": "0.5",
    "gain": "1500.0",
    "catch_up_lead": "0.0",
    "max_angular_accel_rad_s2": "50.0",
}


def f(x):
    return "–" if x is None else f"{x:.3f}"


def with_before(binary, opts, out_dir):
    """The row's options on its effective configuration (`demo --print-config`, the binary's
    own writing of it) with BEFORE's keys set."""
    text = subprocess.run([binary, "demo", "--print-config"] + opts,
                          capture_output=True, text=True, check=True).stdout
    for key, value in BEFORE.items():
        text, n = re.subn(rf"^{key} = \S+", f"{key} = {value}", text, flags=re.M)
        if n != 1:
            raise SystemExit(f"{key}: {n} lines in the printed configuration, expected one")
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, "before.toml")
    with open(path, "w") as fh:
        fh.write(text)
    rest = list(opts)
    if "--config" in rest:
        i = rest.index("--config")
        del rest[i:i + 2]
    return ["--config", path] + rest


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default="target/release/mocomp")
    ap.add_argument("--out", default="/tmp/oracle-table")
    ap.add_argument("--before", action="store_true",
                    help="also run each row with the settings before issue 33's improvements")
    a = ap.parse_args()
    print("| run | settings | controller | d RMS | d max | translation RMS (mm) | excess d RMS "
          "| excess d max | prediction's share RMS (mm) | execution's share RMS (mm) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name, opts in RUNS:
        settings = [("before", "before"), ("after", "now")] if a.before else [("now", "now")]
        for tag, label in settings:
            out_dir = os.path.join(a.out, f"{name}-{tag}")
            run_opts = with_before(a.bin, opts, out_dir) if tag == "before" else opts
            out = subprocess.run(
                [a.bin, "demo", "--controllers", "paper,mocomp,oracle", "--json", "--quiet",
                 "--out", out_dir] + run_opts,
                capture_output=True, text=True, check=True)
            j = json.loads(out.stdout)
            for r in j["controllers"]:
                ex = r.get("excess_over_oracle") or {}
                share = lambda k: (r.get(k) or {}).get("rms")
                print(f"| {name} | {label} | {r['controller']} | {r['d_rms']:.3f} "
                      f"| {r['d_max']:.3f} | {r['translation_mm_rms']:.3f} "
                      f"| {f(ex.get('d_rms'))} | {f(ex.get('d_max'))} "
                      f"| {f(share('prediction_mm'))} | {f(share('execution_mm'))} |")
            if j.get("head_robot_lags"):
                print(f"| {name} | {label} | head robot lagged {j['head_robot_lagged_s']:.2f} s "
                      f"in {len(j['head_robot_lags'])} intervals | | | | | | | |")


if __name__ == "__main__":
    main()
