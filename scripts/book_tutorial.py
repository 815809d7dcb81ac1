#!/usr/bin/env python3
"""Runs every command of the book's tutorial, so the book cannot go stale.

    python3 scripts/book_tutorial.py BIN_DIR PAGE.md [PAGE.md ...]

Every fenced block marked `sh` on the pages is run, in page order, line by line with
`bash -eo pipefail`, in one fresh directory per page holding a link to the repository's
`examples/`, with BIN_DIR (where `mocomp` is) first on the path. A command that fails, or runs
past its limit, fails the run, naming the page, the line and what it printed. Blocks marked
`text` are shown, not run (installing, and commands of a real cell).
"""

import os
import re
import subprocess
import sys
import tempfile

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
LIMIT_S = 900
FENCE = re.compile(r"^```(\S*)\s*$")


def commands(path):
    """(line number, command) of each line of the page's `sh` blocks."""
    out, lang = [], None
    for n, line in enumerate(open(path, encoding="utf-8").read().splitlines(), 1):
        m = FENCE.match(line)
        if m:
            lang = m.group(1) if lang is None else None
            continue
        if lang == "sh" and line.strip() and not line.lstrip().startswith("#"):
            out.append((n, line.strip()))
    if lang is not None:
        sys.exit(f"{path}: a code block is not closed")
    return out


def main():
    bin_dir, pages = os.path.abspath(sys.argv[1]), sys.argv[2:]
    env = dict(os.environ, PATH=bin_dir + os.pathsep + os.environ.get("PATH", ""))
    total = 0
    for page in pages:
        cmds = commands(page)
        with tempfile.TemporaryDirectory(prefix="mocomp-tutorial-") as work:
            os.symlink(os.path.join(os.path.abspath(ROOT), "examples"),
                       os.path.join(work, "examples"))
            for n, cmd in cmds:
                print(f"{os.path.relpath(page, ROOT)}:{n}: {cmd}", flush=True)
                try:
                    r = subprocess.run(["bash", "-eo", "pipefail", "-c", cmd], cwd=work, env=env,
                                       capture_output=True, text=True, timeout=LIMIT_S)
                except subprocess.TimeoutExpired:
                    sys.exit(f"{page}:{n}: `{cmd}` ran past {LIMIT_S} s")
                if r.returncode != 0:
                    sys.exit(f"{page}:{n}: `{cmd}` exited {r.returncode}\n--- stdout\n"
                             f"{r.stdout[-4000:]}\n--- stderr\n{r.stderr[-4000:]}")
                total += 1
    if total == 0:
        sys.exit("no tutorial command found: the pages have no `sh` block")
    print(f"the tutorial's {total} commands ran")


if __name__ == "__main__":
    main()
