"""The live loop against a controller in another process, as a real robot is (issue 29).

    cargo build --release --bin mocomp
    python3 bench/external_controller.py [--runs 3] [--seconds 14] [--busy 0] [--stalls 0]

Each run starts `mocomp ursim --model ur3e` as a process of its own (SCHED_FIFO 49, its own start
pose), then `mocomp run` on examples/run-sim.toml with `simulate = false` against it. Starts:
  home      UR's home, the arm upright (the goal is on another IK branch: a joint-space transit);
  behind    the flange beyond the head, the coil facing down (the shell path on its own branch);
  far       the simulator's default working pose, the flange on the other side of the base;
  in-proc   the far start again, but the controller in mocomp's own process (`simulate = true`,
            `initial_joints_rad`): the reference the external runs are compared with.
`--busy N` runs N CPU hogs (stress-ng, or Python loops) beside every run; `--stalls N` stops the
external controller's process (SIGSTOP) N times for 10-45 ms (seeded) once the loop tracks.
Prints, per run: the first planned motion (Transit's joint travel or the shell's Resume), the time
to Reached, the deviation RMS and p95 while tracking, missed cycles, RobotStale holds and the
protective stops the controller logged; then medians per start. Nothing here is a test: the
tests are crates/mocomp-cli/tests/external_controller.rs.
"""

import argparse
import json
import os
import random
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
MOCOMP = os.path.join(ROOT, "target", "release", "mocomp")
CONFIG = os.path.join(ROOT, "examples", "run-sim.toml")

STARTS = {
    "home": [0.0, -1.5708, 0.0, -1.5708, 0.0, 0.0],
    "behind": [0.0225, -2.5706, -0.8144, -1.3275, 1.5692, -1.5483],
    "far": [0.0, -1.3, 1.6, -1.87, -1.57, 0.0],
}


def config(directory, host, external, start):
    text = open(CONFIG).read()
    text = re.sub(r'^host = "127\.0\.0\.2"', f'host = "{host}"', text, count=1, flags=re.M)
    if external:
        text = re.sub(r"^simulate = true", "simulate = false", text, count=1, flags=re.M)
    else:
        text = re.sub(
            r"^# initial_joints_rad = .*$",
            f"initial_joints_rad = {json.dumps(start)}",
            text,
            count=1,
            flags=re.M,
        )
    path = os.path.join(directory, "run.toml")
    open(path, "w").write(text)
    return path


def stall(pid, n, seed):
    rng = random.Random(seed)
    time.sleep(8.0)
    for _ in range(n):
        os.kill(pid, signal.SIGSTOP)
        time.sleep(rng.uniform(0.010, 0.045))
        os.kill(pid, signal.SIGCONT)
        time.sleep(rng.uniform(0.15, 0.35))


def one(name, host, seconds, stalls, seed):
    external = name != "in-proc"
    start = STARTS["far" if name == "in-proc" else name]
    with tempfile.TemporaryDirectory(prefix="mocomp-bench-external-") as d:
        cfg = config(d, host, external, start)
        ursim = None
        if external:
            ursim = subprocess.Popen(
                [MOCOMP, "ursim", "--model", "ur3e", "--host", host,
                 "--initial-joints=" + ",".join(str(q) for q in start),
                 "--seconds", str(seconds + 5)],
                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            )
            line = ursim.stdout.readline()  # the addresses: it serves
            if not line:
                sys.exit(f"ursim did not start on {host}")
        staller = None
        if ursim is not None and stalls:
            staller = threading.Thread(target=stall, args=(ursim.pid, stalls, seed))
            staller.start()
        out = subprocess.run(
            [MOCOMP, "run", "--config", cfg, "--seconds", str(seconds), "--quiet", "--json"],
            capture_output=True, text=True, timeout=seconds + 60,
        )
        if staller:
            staller.join()
        log = ""
        if ursim is not None:
            ursim.send_signal(signal.SIGINT)
            try:
                log, _ = ursim.communicate(timeout=10)
            except subprocess.TimeoutExpired:
                ursim.kill()
                log, _ = ursim.communicate()
        if out.returncode != 0:
            sys.exit(f"{name}: mocomp run failed: {out.stderr}")
        v = json.loads(out.stdout)
    events = v["event_log"]
    first = next((e[1] for e in events if e[1].startswith(("Transit", "Resume"))), "-")
    reached = next((e[0] for e in events if e[1] == "Reached"), None)
    stops = [l for l in log.splitlines() if "protective" in l.lower() or "C204" in l]
    return {
        "start": name,
        "first": first,
        "reached_s": reached,
        "rms_mm": v["deviation_rms_mm"],
        "p95_mm": v["deviation_p95_mm"],
        "missed": v["missed_cycles"],
        "stale_holds": v["robot_stale_holds"],
        "protective_stops": max(len(stops), v["protective_stops"]),
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seconds", type=int, default=14)
    ap.add_argument("--busy", type=int, default=0)
    ap.add_argument("--stalls", type=int, default=0)
    a = ap.parse_args()
    if not os.path.exists(MOCOMP):
        sys.exit("build first: cargo build --release --bin mocomp")
    hogs = []
    if a.busy:
        if shutil.which("stress-ng"):
            hogs.append(subprocess.Popen(["stress-ng", "--cpu", str(a.busy), "--quiet"]))
        else:
            hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(a.busy)]
    rows = []
    try:
        for r in range(a.runs):
            for k, name in enumerate(["home", "behind", "far", "in-proc"]):
                row = one(name, f"127.0.3.{10 + k}", a.seconds, a.stalls, 29 + r)
                rows.append(row)
                print(json.dumps(row), flush=True)
    finally:
        for h in hogs:
            h.terminate()
            h.wait()
    print("\nstart     reached_s (median)  rms_mm  p95_mm  missed  stale holds  protective stops")
    for name in ["home", "behind", "far", "in-proc"]:
        rs = [r for r in rows if r["start"] == name]
        reached = [r["reached_s"] for r in rs if r["reached_s"] is not None]
        med = lambda k: statistics.median(r[k] for r in rs)
        print(
            f"{name:9} {statistics.median(reached) if reached else float('nan'):8.2f} "
            f"({len(reached)}/{len(rs)} reached)  {med('rms_mm'):6.2f}  {med('p95_mm'):6.2f}  "
            f"{med('missed'):6.0f}  {sum(r['stale_holds'] for r in rs):11d}  "
            f"{sum(r['protective_stops'] for r in rs):16d}"
        )


if __name__ == "__main__":
    main()
