"""The JSON-lines loop shared by the interop helpers: one request per stdin line, one answer per
stdout line; an exception becomes {"error": ...} and the helper keeps serving.

With capture_stdout, the process's fd 1 is pointed at a temporary file (for peers whose C++ code
prints to stdout) and each answer carries "peer_warnings": the lines printed while serving it.
"""

import ctypes
import json
import os
import sys
import tempfile


def serve(handle, capture_stdout=False):
    sys.stdout.flush()
    proto = os.fdopen(os.dup(1), "w", buffering=1)
    captured = None
    libc = None
    if capture_stdout:
        libc = ctypes.CDLL(None)
        captured = tempfile.TemporaryFile(mode="w+b")
        os.dup2(captured.fileno(), 1)
    for line in sys.stdin:
        line = line.strip()
        if not line:
            continue
        try:
            answer = handle(json.loads(line))
        except Exception as exc:  # report and keep serving
            answer = {"error": f"{type(exc).__name__}: {exc}"}
        if captured is not None:
            libc.fflush(None)  # C++ output buffered by stdio
            captured.seek(0)
            printed = captured.read().decode(errors="replace")
            captured.seek(0)
            captured.truncate()
            answer["peer_warnings"] = sum(1 for ln in printed.splitlines() if ln.strip())
        proto.write(json.dumps(answer) + "\n")
