"""What holding /dev/cpu_dma_latency at 0 µs does to a virtual machine (`[realtime]
prevent_cpu_sleep`).

    sudo python3 bench/cpu_sleep_on_vm.py [--rounds 2] [--seconds 60]

Each round runs two phases, one with the PM QoS request held (idle CPUs poll) and one without.
In each: one busy process (a Python loop, as a test or a build beside the loop would be), and on
every CPU a SCHED_FIFO 49 thread pinned to it that sleeps 2 ms and measures how late it woke, as
the loop and the simulated controller do. Prints per phase: the host's steal time (/proc/stat,
jiffies), the worst wake-up and the wake-ups later than 20 ms per CPU; then the medians per mode.
A wake-up 100 ms late is a vCPU its host froze (its CPU-time period), and a 100 ms freeze stops a
robot's program on its 50 ms watchdog. Needs root (SCHED_FIFO and the PM QoS file). Nothing here
is a test.
"""

import argparse
import multiprocessing
import os
import statistics
import struct
import time


def steal_jiffies():
    with open("/proc/stat") as f:
        return int(f.readline().split()[8])


def probe(cpu, seconds, out):
    os.sched_setaffinity(0, {cpu})
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(49))
    worst, late = 0.0, 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        t = time.monotonic()
        time.sleep(0.002)
        lag = time.monotonic() - t - 0.002
        worst = max(worst, lag)
        late += lag > 0.020
    out.put((cpu, worst, late))


def busy(seconds):
    end = time.monotonic() + seconds
    x = 0
    while time.monotonic() < end:
        x += 1


def phase(hold, seconds):
    fd = None
    if hold:
        fd = os.open("/dev/cpu_dma_latency", os.O_WRONLY)
        os.write(fd, struct.pack("i", 0))
    s0 = steal_jiffies()
    out = multiprocessing.Queue()
    hog = multiprocessing.Process(target=busy, args=(seconds + 1,))
    hog.start()
    probes = [
        multiprocessing.Process(target=probe, args=(c, seconds, out))
        for c in range(os.cpu_count())
    ]
    for p in probes:
        p.start()
    results = sorted(out.get() for _ in probes)
    for p in probes + [hog]:
        p.join()
    steal = steal_jiffies() - s0
    if fd is not None:
        os.close(fd)
    return steal, results


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args()
    by_mode = {"held": [], "not held": []}
    for r in range(a.rounds):
        for hold in (True, False):
            steal, res = phase(hold, a.seconds)
            mode = "held" if hold else "not held"
            by_mode[mode].append((steal, max(w for _, w, _ in res), sum(n for *_, n in res)))
            cpus = ", ".join(
                f"cpu{c} worst {w * 1e3:.1f} ms, {n} > 20 ms" for c, w, n in res
            )
            print(f"round {r + 1}, latency {mode}: steal {steal} jiffies; {cpus}", flush=True)
    for mode, rows in by_mode.items():
        print(
            f"{mode}: median steal {statistics.median(s for s, _, _ in rows):.0f} jiffies per "
            f"{a.seconds:.0f} s, worst wake-up {statistics.median(w for _, w, _ in rows) * 1e3:.1f} ms, "
            f"{statistics.median(n for *_, n in rows):.0f} wake-ups > 20 ms"
        )


if __name__ == "__main__":
    main()
