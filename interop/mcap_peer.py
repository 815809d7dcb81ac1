"""Read an MCAP recording with the PyPI `mcap` reader and `mcap-ros2-support` (which decodes each
message with the ROS 2 `.msg` schema stored in the file), for mocomp's tests.

Requests (one JSON line each):
  {"op": "version"}        -> {"version": "0.6.0"}  (mcap-ros2-support)
  {"op": "read", "path": p} -> {"profile": str, "counts": {topic: n}, "schemas": {topic: name},
                               "first": {topic: message as JSON}, "last": {...},
                               "cycle_t": [t_s of every /mocomp/cycle message],
                               "cycle_controller": [its controller],
                               "in_time_order": bool (log times never go back), "undecoded": n}
Messages are read in the order the file has them (not sorted by time). Every message is decoded;
one that does not decode counts in "undecoded".
"""

from importlib import metadata as md

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from jsonlines import serve


def to_json(x):
    if isinstance(x, (list, tuple)):
        return [to_json(v) for v in x]
    if hasattr(x, "__slots__"):
        return {k: to_json(getattr(x, k)) for k in x.__slots__}
    if isinstance(x, float) and x != x:
        return None
    if isinstance(x, bytes):
        return list(x)
    return x


def read(path):
    counts, schemas, first, last, cycle_t, cycle_controller = {}, {}, {}, {}, [], []
    undecoded, previous, in_time_order = 0, 0, True
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        profile = reader.get_header().profile
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            t = channel.topic
            in_time_order = in_time_order and message.log_time >= previous
            previous = message.log_time
            counts[t] = counts.get(t, 0) + 1
            schemas[t] = schema.name
            if decoded is None:
                undecoded += 1
                continue
            j = to_json(decoded)
            first.setdefault(t, j)
            last[t] = j
            if t == "/mocomp/cycle":
                cycle_t.append(decoded.t_s)
                cycle_controller.append(decoded.controller)
    return {"profile": profile, "counts": counts, "schemas": schemas, "first": first,
            "last": last, "cycle_t": cycle_t, "cycle_controller": cycle_controller,
            "in_time_order": in_time_order, "undecoded": undecoded}


def handle(req):
    op = req.get("op")
    if op == "version":
        return {"version": md.version("mcap-ros2-support")}
    if op == "read":
        return read(req["path"])
    return {"error": f"unknown op {op!r}"}


if __name__ == "__main__":
    serve(handle)
