"""Interop helper: SDU's ur_rtde (PyPI `ur-rtde`) as a client of a UR controller (ours:
mocomp-ursim). One JSON request per line, one JSON answer per line (see jsonlines.py).

Ops: version; receive (RTDEReceiveInterface: rate and values); control_connect (RTDEControlInterface
plus a receiver); moveJ; servo_stream (servoJ at the controller rate with initPeriod/waitPeriod);
speedJ; speedStop; servoStop; stopJ; zeroFtSensor (with the TCP force before and after);
stopScript; disconnect; io (RTDEIOInterface: digital outputs set and read back, inputs read);
moveL (asynchronous, the TCP's path sampled); teachMode (not emulated: refused); watch (a
receiver on its own thread recording the fastest joint's speed of every new state, placed on
CLOCK_MONOTONIC by the controller's own timestamps), still_after (when, after t0, the arm came to stand and stayed), top_speed.
"""

import importlib.metadata
import math
import statistics
import threading
import time

from jsonlines import serve

import rtde_control
import rtde_io
import rtde_receive

state = {}


def pctl(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(p / 100.0 * (len(xs) - 1))))]


def receive(req):
    r = rtde_receive.RTDEReceiveInterface(req["host"], req.get("frequency", -1.0))
    t_end = time.monotonic() + req.get("seconds", 1.0)
    stamps = []
    last = None
    while time.monotonic() < t_end:
        ts = r.getTimestamp()
        if ts != last:
            stamps.append(ts)
            last = ts
        time.sleep(0.0002)
    steps = [b - a for a, b in zip(stamps, stamps[1:]) if b > a]
    out = {
        "distinct": len(stamps),
        # The smallest step between timestamps seen: one controller period when the stream comes
        # at the controller's rate, however many of them a busy machine's polling missed.
        "min_step": min(steps) if steps else None,
        "first_ts": stamps[0],
        "last_ts": stamps[-1],
        "actual_q": list(r.getActualQ()),
        "target_q": list(r.getTargetQ()),
        "tcp": list(r.getActualTCPPose()),
        "tcp_force": list(r.getActualTCPForce()),
        "robot_mode": r.getRobotMode(),
        "safety_mode": r.getSafetyMode(),
        "runtime_state": r.getRuntimeState(),
        "speed_scaling": r.getSpeedScaling(),
        "joint_mode": list(r.getJointMode()),
        "protective_stopped": r.isProtectiveStopped(),
    }
    r.disconnect()
    return out


def watch(req):
    # A third party's view of the arm, beside whatever else is connected: every new state's
    # arrival (time.monotonic is CLOCK_MONOTONIC, the same clock the test stamps its faults
    # with), the controller's own timestamp of it, and its fastest joint's speed.
    r = rtde_receive.RTDEReceiveInterface(req["host"], -1.0)
    samples = []
    stop = threading.Event()

    def run():
        last = None
        while not stop.is_set():
            ts = r.getTimestamp()
            if ts != last:
                last = ts
                qd = r.getActualQd()
                samples.append((time.monotonic(), ts, max(abs(v) for v in qd)))
            time.sleep(0.0002)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    state["watch"] = (r, samples, stop, t)
    return {"ok": True}


def on_monotonic():
    # Each state at the time the controller stamped it, on CLOCK_MONOTONIC. A monitor on a busy
    # machine receives late and in bursts; the controller (at its real-time priority) stamps on
    # time, so a state's arrival delay is never negative and the smallest one seen is within a
    # poll (0.2 ms) of the true offset. That offset is not one constant: a simulated controller
    # stopped longer than it makes up gives the cycles up, and from then on its clock runs behind
    # the wall clock by them (a real one never falls behind; the offset then stays constant).
    # Lost cycles only ever add to the lag, so a state's offset is at most the smallest delay seen
    # at or after it: the minimum over what follows, taken from the end, tracks each step.
    _, samples, _, _ = state["watch"]
    xs = list(samples)
    out = []
    offset = math.inf
    for m, ts, v in reversed(xs):
        offset = min(offset, m - ts)
        out.append((ts + offset, v))
    out.reverse()
    return out


def lag_s():
    # How far the controller's clock fell behind the wall clock while watched (its given-up
    # cycles), for a failing test's message.
    _, samples, _, _ = state["watch"]
    xs = list(samples)
    if not xs:
        return None
    return min(m - ts for (m, ts, _) in xs[-50:]) - min(m - ts for (m, ts, _) in xs[:50])


def still_after(req):
    # The first state at or after t0 from which every state for stay_s is below 1 mrad/s.
    xs = [s for s in on_monotonic() if s[0] >= req["t0"]]
    stay = req["stay_s"]
    for i, (t, _) in enumerate(xs):
        if xs[-1][0] < t + stay:
            break
        if all(v < 1e-3 for (u, v) in xs[i:] if u < t + stay):
            return {"still_s": t - req["t0"], "samples": len(xs), "lag_s": lag_s()}
    return {"still_s": None, "samples": len(xs), "lag_s": lag_s()}


def top_speed(req):
    vs = [v for (t, v) in on_monotonic() if req["from"] <= t < req["to"]]
    return {"speed": max(vs) if vs else None, "samples": len(vs)}


def wait_for(f, seconds=5.0):
    # How long a package takes here depends on how busy the machine is: wait with a deadline.
    deadline = time.monotonic() + seconds
    while not f() and time.monotonic() < deadline:
        time.sleep(0.001)
    return f()


def io(req):
    # ur_rtde's io_example.py: digital output 7 high, read back through the receive interface;
    # then an input the controller's world drives, and an analog output.
    host = req["host"]
    i = rtde_io.RTDEIOInterface(host)
    r = rtde_receive.RTDEReceiveInterface(host)
    out = {}
    out["set_high"] = i.setStandardDigitalOut(7, True)
    out["out7_high"] = wait_for(lambda: r.getDigitalOutState(7))
    out["configurable"] = i.setConfigurableDigitalOut(2, True)
    out["conf2_high"] = wait_for(lambda: r.getActualDigitalOutputBits() & (1 << 10) != 0)
    out["set_low"] = i.setStandardDigitalOut(7, False)
    out["out7_low"] = wait_for(lambda: not r.getDigitalOutState(7))
    out["bits"] = r.getActualDigitalOutputBits()
    out["in_bits"] = r.getActualDigitalInputBits()
    out["in3"] = r.getDigitalInState(3)
    i.disconnect()
    r.disconnect()
    return out


def control_connect(req):
    host = req["host"]
    t0 = time.monotonic()
    c = rtde_control.RTDEControlInterface(host)
    connect_ms = (time.monotonic() - t0) * 1e3
    r = rtde_receive.RTDEReceiveInterface(host)
    state["c"], state["r"] = c, r
    return {"connect_ms": connect_ms, "q": list(r.getActualQ()), "steptime": c.getStepTime()}


def wait_steady(r, seconds=0.05):
    time.sleep(seconds)
    return list(r.getActualQ())


def handle(req):
    op = req["op"]
    if op == "version":
        return {"version": importlib.metadata.version("ur-rtde")}
    if op == "watch":
        return watch(req)
    if op == "still_after":
        return still_after(req)
    if op == "top_speed":
        return top_speed(req)
    if op == "receive":
        return receive(req)
    if op == "control_connect":
        return control_connect(req)
    if op == "io":
        return io(req)
    c, r = state.get("c"), state.get("r")
    if c is None:
        raise RuntimeError("control_connect first")
    if op == "moveJ":
        ok = c.moveJ(req["q"], req.get("speed", 1.05), req.get("acc", 1.4))
        return {"ok": ok, "q": wait_steady(r)}
    if op == "servo_stream":
        dt = req.get("dt", 0.002)
        n = int(req["seconds"] / dt)
        amp = req["amplitude"]
        q0 = list(r.getActualQ())
        periods, calls, errs = [], [], []
        target = q0
        last = None
        for k in range(n):
            t_start = c.initPeriod()
            now = time.perf_counter()
            if last is not None:
                periods.append((now - last) * 1e3)
            last = now
            s = k * dt
            target = list(q0)
            target[0] = q0[0] + amp * (1 - math.cos(2 * s))
            target[5] = q0[5] + amp * math.sin(3 * s)
            t0 = time.perf_counter()
            c.servoJ(target, 0.0, 0.0, dt, req.get("lookahead", 0.1), req.get("gain", 300))
            calls.append((time.perf_counter() - t0) * 1e6)
            if k * dt > 0.5:
                # The servo lags a moving target: compare with the target a lookahead ago.
                errs.append(abs(r.getActualQ()[0] - target[0]))
            c.waitPeriod(t_start)
        c.servoStop(10.0)
        return {
            "n": n,
            "period_median_ms": statistics.median(periods),
            "period_p99_ms": pctl(periods, 99),
            "period_max_ms": max(periods),
            "call_median_us": statistics.median(calls),
            "max_err": max(errs),
            "final_target": target,
            "final_actual": wait_steady(r, 0.3),
        }
    if op == "speedJ":
        ok = c.speedJ(req["qd"], req.get("acc", 0.5), 0.0)
        time.sleep(req.get("seconds", 0.5))
        return {"ok": ok, "qd": list(r.getActualQd()), "q": list(r.getActualQ())}
    if op == "speedStop":
        c.speedStop(req.get("acc", 10.0))
        return {"qd": list(r.getActualQd()), "q": wait_steady(r)}
    if op == "servoStop":
        c.servoStop(req.get("acc", 10.0))
        return {"q": wait_steady(r)}
    if op == "stopJ":
        c.stopJ(req.get("acc", 2.0), False)
        return {"qd": list(r.getActualQd()), "q": wait_steady(r)}
    if op == "stopScript":
        c.stopScript()
        time.sleep(0.05)
        return {"runtime_state": r.getRuntimeState()}
    if op == "moveL":
        # Asynchronous, so the TCP's path can be sampled on the way; then wait until it stops.
        start = list(r.getActualTCPPose())
        target = [start[i] + req["offset"][i] for i in range(6)]
        ok = c.moveL(target, req.get("speed", 0.1), req.get("acc", 0.5), True)
        path = []
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            p = list(r.getActualTCPPose())
            path.append(p[:3])
            if max(abs(p[i] - target[i]) for i in range(3)) < 1e-6:
                break
            time.sleep(0.005)
        time.sleep(0.05)
        return {"ok": ok, "start": start, "target": target, "path": path,
                "final": list(r.getActualTCPPose())}
    if op == "teachMode":
        # Not emulated by our simulator: it must refuse, not pretend.
        try:
            ok, raised = c.teachMode(), ""
        except Exception as e:  # ur_rtde may raise when its control script has stopped
            ok, raised = False, str(e)
        return {"ok": ok, "raised": raised}
    if op == "zeroFtSensor":
        # Wait (with a deadline) for a reading, zero, then wait for the zero to arrive: how long
        # a package takes here depends on how busy the machine is.
        deadline = time.monotonic() + 5.0
        while not any(r.getActualTCPForce()) and time.monotonic() < deadline:
            time.sleep(0.001)
        before = list(r.getActualTCPForce())
        ok = c.zeroFtSensor()
        while any(r.getActualTCPForce()) and time.monotonic() < deadline:
            time.sleep(0.001)
        return {"ok": ok, "before": before, "after": list(r.getActualTCPForce())}
    if op == "disconnect":
        c.disconnect()
        r.disconnect()
        state.clear()
        return {"ok": True}
    raise ValueError(f"unknown op {op}")


if __name__ == "__main__":
    serve(handle)
