#!/usr/bin/env bash
# Does the suite, and the live loop, care how busy the machine is?
#
#   scripts/stress.sh [--runs N] [--busy M] [--run-seconds S] [--run-busy K] [--no-tests] [--no-run]
#
# 1. Runs the full test command (scripts/test.sh) N times in a row (default 10) with M busy
#    processes beside it (default 1), and prints how many passed and failed (each failing run's
#    log is kept in target/stress/).
# 2. Runs `mocomp run` on examples/run-sim.toml for S seconds (default 12) unloaded, then with K
#    busy processes beside it (default 2), and prints for each: missed cycles, cycle period p99,
#    cycle compute p99, deviation RMS/p95, holds (robot state stale, protective stops) and the
#    real-time scheduling it got.
#
# A busy process is a plain shell busy loop at normal priority (a neuronavigation PC's viewer,
# a virus scanner). Exit status: 0 when every test run passed and the loaded run kept under 1 %
# missed cycles with no protective stop and no stale-state hold; 1 otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."

runs=10 busy=1 run_seconds=12 run_busy=2 tests=1 live=1
while [ $# -gt 0 ]; do
  case "$1" in
    --runs) runs=$2; shift 2 ;;
    --busy) busy=$2; shift 2 ;;
    --run-seconds) run_seconds=$2; shift 2 ;;
    --run-busy) run_busy=$2; shift 2 ;;
    --no-tests) tests=0; shift ;;
    --no-run) live=0; shift ;;
    -h|--help) sed -n 2,17p "$0"; exit 0 ;;
    *) echo "stress.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

pids=()
start_busy() {
  for _ in $(seq 1 "$1"); do
    sh -c 'while :; do :; done' &
    pids+=($!)
  done
}
stop_busy() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
  pids=()
}
trap stop_busy EXIT

status=0
mkdir -p target/stress

if [ "$tests" = 1 ]; then
  pass=0 fail=0
  start_busy "$busy"
  for i in $(seq 1 "$runs"); do
    log="target/stress/test-run-$i.log"
    t0=$(date +%s)
    if scripts/test.sh >"$log" 2>&1; then
      pass=$((pass + 1)); verdict=passed; rm -f "$log"
    else
      fail=$((fail + 1)); verdict="FAILED (log: $log)"; status=1
    fi
    printf 'test run %d/%d with %d busy: %s in %d s\n' "$i" "$runs" "$busy" "$verdict" $(($(date +%s) - t0))
  done
  stop_busy
  printf '\nfull test command, %d runs with %d busy process(es): %d passed, %d failed\n\n' \
    "$runs" "$busy" "$pass" "$fail"
fi

if [ "$live" = 1 ]; then
  cargo build --release --locked --quiet --bin mocomp
  steal() { awk '/^cpu /{print $9, $2+$3+$4+$5+$6+$7+$8+$9}' /proc/stat; }
  report() { # $1 = busy processes
    start_busy "$1"
    local before after
    before=$(steal)
    ./target/release/mocomp run --config examples/run-sim.toml --seconds "$run_seconds" \
      --quiet --json 2>"target/stress/run-busy-$1.err" >"target/stress/run-busy-$1.json"
    after=$(steal)
    stop_busy
    # Time the hypervisor gave this VM's CPUs to others (0 on bare metal): noise no priority helps.
    echo "$before $after" | awk '{printf "%.2f\n", 100 * ($3 - $1) / (($4 - $2) > 0 ? ($4 - $2) : 1)}' \
      >"target/stress/run-busy-$1.steal"
  }
  report 0
  report "$run_busy"
  python3 - "$run_busy" <<'EOF' || status=1
import json, sys
k = sys.argv[1]
def load(b):
    r = json.load(open(f"target/stress/run-busy-{b}.json"))
    r["steal"] = float(open(f"target/stress/run-busy-{b}.steal").read())
    return r
rows = [("unloaded", load(0)), (f"{k} busy", load(k))]
print(f"{'mocomp run':<10} {'missed':>14} {'period p99':>11} {'compute p50/p99':>16} "
      f"{'dev RMS':>8} {'dev p95':>8} {'holds':>6} {'stale':>6} {'pstops':>7} {'steal':>6}  real time")
for name, r in rows:
    print(f"{name:<10} {r['missed_cycles']:>6} ({r['missed_percent']:5.2f} %) "
          f"{r['period_p99_ms']:>8.3f} ms {r['compute_median_us']:>6.1f}/{r['compute_p99_us']:>5.1f} µs "
          f"{r['deviation_rms_mm']:>5.2f} mm {r['deviation_p95_mm']:>5.2f} mm "
          f"{r['holds']:>6} {r['robot_stale_holds']:>6} {r['protective_stops']:>7} {r['steal']:>5.1f}%  "
          f"{r['realtime']}")
loaded = rows[1][1]
ok = (loaded["missed_percent"] < 1.0 and loaded["protective_stops"] == 0
      and loaded["robot_stale_holds"] == 0)
print("loaded run:", "within the limits (< 1 % missed, no protective stop, no stale hold)"
      if ok else "OUT OF LIMITS")
sys.exit(0 if ok else 1)
EOF
fi
exit $status
