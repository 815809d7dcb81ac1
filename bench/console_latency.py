"""The operator's console: how late the page shows the loop, and whether a connected console
costs the loop anything.

    cargo build --release --bin mocomp
    .venv/bin/python bench/console_latency.py [--runs 3] [--seconds 20]

Each run pair, on examples/run-sim.toml (the simulated UR3e, nodding head):
  A. `mocomp run --json` alone: the cycle's compute median and p99;
  B. `mocomp run --dashboard --json` with the page open in Debian's headless Chromium for the
     whole run (Selenium): the same figures, and the page's loop-to-page latency for every status
     it received (from the cycle that produced the status to the WebSocket message handled in the
     page: wall clock, same machine).
Prints each run and the medians over runs. Nothing is timed in a unit test; this is the
benchmark the book's console page quotes.
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "interop"))
from console_browser import browser  # noqa: E402

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
MOCOMP = os.path.join(ROOT, "target", "release", "mocomp")
CONFIG = os.path.join(ROOT, "examples", "run-sim.toml")


def run_alone(seconds):
    out = subprocess.run(
        [MOCOMP, "run", "--config", CONFIG, "--seconds", str(seconds), "--quiet", "--json"],
        check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def run_with_console(seconds):
    p = subprocess.Popen(
        [MOCOMP, "run", "--config", CONFIG, "--seconds", str(seconds), "--quiet", "--json",
         "--dashboard", "127.0.0.1:0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    url = None
    while url is None:
        line = p.stderr.readline()
        if not line:
            raise RuntimeError("mocomp run ended before printing its dashboard line")
        if line.startswith("dashboard: "):
            url = line.split(" ", 1)[1].strip()
    d = browser()
    try:
        d.get(url)
        # The page stays open until the run ends (its last status says stopped).
        deadline = time.monotonic() + seconds + 30
        while time.monotonic() < deadline:
            if d.execute_script("return window.mocomp.status && !window.mocomp.status.running"):
                break
            time.sleep(0.5)
        lat = [x for x in d.execute_script("return window.mocomp.latencies.slice()") if x == x]
    finally:
        d.quit()
    out, _ = p.communicate(timeout=60)
    return json.loads(out), sorted(lat)


def pct(v, q):
    return v[min(len(v) - 1, int(q * (len(v) - 1) + 0.5))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seconds", type=int, default=20)
    a = ap.parse_args()
    rows = []
    for i in range(a.runs):
        alone = run_alone(a.seconds)
        with_console, lat = run_with_console(a.seconds)
        row = {
            "alone_compute_median_us": alone["compute_median_us"],
            "alone_compute_p99_us": alone["compute_p99_us"],
            "alone_missed_percent": alone["missed_percent"],
            "console_compute_median_us": with_console["compute_median_us"],
            "console_compute_p99_us": with_console["compute_p99_us"],
            "console_missed_percent": with_console["missed_percent"],
            "statuses": len(lat),
            "latency_median_ms": statistics.median(lat),
            "latency_p99_ms": pct(lat, 0.99),
        }
        rows.append(row)
        print(f"run {i + 1}: " + ", ".join(f"{k} {v:.3g}" for k, v in row.items()), flush=True)
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0]}
    print("median over runs: " + ", ".join(f"{k} {v:.3g}" for k, v in med.items()))
    ratio = med["console_compute_p99_us"] / med["alone_compute_p99_us"]
    print(f"compute p99 with the console / without: {ratio:.2f}")


if __name__ == "__main__":
    main()
