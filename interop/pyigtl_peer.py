"""Expose pyigtl (an independent Python OpenIGTLink implementation) to mocomp's tests.

Requests (one JSON line each):
  {"op": "version"}                                  -> {"version": "0.3.4"}
  {"op": "server", "port": p}                        -> starts a pyigtl server on 127.0.0.1:p (0: any
                                                        free port) -> {"ok": true, "port": bound}
  {"op": "client", "port": p}                        -> starts a pyigtl client to 127.0.0.1:p
  {"op": "connected"}                                -> {"connected": bool}
  {"op": "send", "kind": "transform"|"string", "device": d, "matrix": [[4x4 mm]] | "string": s,
   "timestamp": seconds, "header_version": 1|2, "metadata": {k: v}, "message_id": n}
  {"op": "stream", "frames": [{d: [[4x4 mm]], ...}, ...], "rate_hz": r}
                                                     -> in the background, once a client is
                                                        connected: each frame's transforms at
                                                        rate r, one timestamp per frame
                                                        -> {"ok": true}
  {"op": "streamed"}                                 -> {"sent": frames sent so far, "done": bool}
  {"op": "wait", "device": d, "timeout": s}          -> {"found": bool, "type", "matrix",
                                                         "string", "timestamp", "header_version",
                                                         "metadata", "message_id"}
pyigtl's quirks (see peers.md): it does not verify CRCs, drops STATUS and GET_ messages, and keeps
only the newest message per device name.
"""

import threading
import time
from importlib import metadata as md

import numpy as np
import pyigtl
from jsonlines import serve

STATE = {"endpoint": None, "sent": 0, "done": False}


def stream(ep, frames, rate_hz):
    deadline = time.monotonic() + 20
    while not ep.is_connected() and time.monotonic() < deadline:
        time.sleep(0.01)
    period = 1.0 / rate_hz
    start = time.monotonic()
    for i, frame in enumerate(frames):
        stamp = time.time()
        for device, matrix in frame.items():
            m = pyigtl.TransformMessage(np.array(matrix), timestamp=stamp, device_name=device)
            ep.send_message(m, wait=True)
        STATE["sent"] = i + 1
        pause = start + (i + 1) * period - time.monotonic()
        if pause > 0:
            time.sleep(pause)
    STATE["done"] = True


def describe(m):
    out = {
        "found": True,
        "type": type(m).__name__,
        "timestamp": m.timestamp,
        "header_version": m.header_version,
        "metadata": dict(m.metadata),
        "message_id": m.message_id,
    }
    if isinstance(m, pyigtl.TransformMessage):
        out["matrix"] = np.asarray(m.matrix, dtype=float).tolist()
    if isinstance(m, pyigtl.StringMessage):
        out["string"] = m.string
    return out


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": md.version("pyigtl")}
    if op == "server":
        STATE["endpoint"] = pyigtl.OpenIGTLinkServer(port=int(req["port"]), local_server=True)
        return {"ok": True, "port": STATE["endpoint"].server_address[1]}
    if op == "client":
        STATE["endpoint"] = pyigtl.OpenIGTLinkClient(host="127.0.0.1", port=int(req["port"]))
        return {"ok": True}
    ep = STATE["endpoint"]
    if op == "connected":
        return {"connected": bool(ep.is_connected())}
    if op == "send":
        if req["kind"] == "transform":
            m = pyigtl.TransformMessage(np.array(req["matrix"]), timestamp=req["timestamp"], device_name=req["device"])
        else:
            m = pyigtl.StringMessage(req["string"], timestamp=req["timestamp"], device_name=req["device"])
        m.header_version = int(req.get("header_version", 1))
        m.metadata = dict(req.get("metadata", {}))
        m.message_id = int(req.get("message_id", 0))
        ep.send_message(m, wait=True)
        return {"ok": True}
    if op == "stream":
        STATE["sent"], STATE["done"] = 0, False
        threading.Thread(target=stream, args=(ep, req["frames"], float(req["rate_hz"])), daemon=True).start()
        return {"ok": True}
    if op == "streamed":
        return {"sent": STATE["sent"], "done": STATE["done"]}
    if op == "wait":
        m = ep.wait_for_message(req["device"], timeout=float(req.get("timeout", 5)))
        return {"found": False} if m is None else describe(m)
    return {"error": f"unknown op {op!r}"}


if __name__ == "__main__":
    serve(handle)
