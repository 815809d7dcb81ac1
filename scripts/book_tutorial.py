#!/usr/bin/env python3
"""Runs every command of the book's tutorials, so the book cannot go stale.

    python3 scripts/book_tutorial.py BIN_DIR PAGE.md [PAGE.md ...]

Every fenced block marked `sh` on the pages is run, in page order, as one script with
`bash -eo pipefail` (so a block may write a file with a here-document), in one fresh directory
per page that holds links to the repository's `examples/` and `crates/` (the tutorials name the
repository's files as a reader at its root would), with BIN_DIR (where `mocomp` is) first on the
path and a cache of its own (`MOCOMP_CACHE_DIR`), so a page starts from nothing. A block that
fails, or runs past its limit, fails the run, naming the page, the block's first line and what
it printed. Blocks marked `text` are shown, not run (installing, and commands of a real cell).
"""

import os
import re
import subprocess
import sys
import tempfile
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
LIMIT_S = 900
FENCE = re.compile(r"^```(\S*)\s*$")
LINKED = ("examples", "crates")


def blocks(path):
    """(line number of the block's first line, the block's text) of each `sh` block."""
    out, lang, start, body = [], None, 0, []
    for n, line in enumerate(open(path, encoding="utf-8").read().splitlines(), 1):
        m = FENCE.match(line)
        if m and (lang is None or not m.group(1)):
            if lang is None:
                lang, start, body = m.group(1), n + 1, []
            else:
                if lang == "sh" and any(b.strip() for b in body):
                    out.append((start, "\n".join(body)))
                lang = None
            continue
        if lang is not None:
            body.append(line)
    if lang is not None:
        sys.exit(f"{path}: a code block is not closed")
    return out


def run_page(page, env):
    """Runs the page's blocks in a fresh directory; returns how many ran."""
    with tempfile.TemporaryDirectory(prefix="mocomp-tutorial-") as work:
        for name in LINKED:
            os.symlink(os.path.join(os.path.abspath(ROOT), name), os.path.join(work, name))
        page_env = dict(env, MOCOMP_CACHE_DIR=os.path.join(work, ".cache"))
        todo = blocks(page)
        for n, block in todo:
            first = block.strip().splitlines()[0]
            print(f"{os.path.relpath(page, ROOT)}:{n}: {first}", flush=True)
            began = time.monotonic()
            try:
                r = subprocess.run(["bash", "-eo", "pipefail", "-c", block], cwd=work,
                                   env=page_env, capture_output=True, text=True,
                                   timeout=LIMIT_S)
            except subprocess.TimeoutExpired:
                sys.exit(f"{page}:{n}: the block ran past {LIMIT_S} s:\n{block}")
            if r.returncode != 0:
                sys.exit(f"{page}:{n}: the block exited {r.returncode}:\n{block}\n--- stdout\n"
                         f"{r.stdout[-4000:]}\n--- stderr\n{r.stderr[-4000:]}")
            print(f"  {time.monotonic() - began:.1f} s", flush=True)
        return len(todo)


def main():
    bin_dir, pages = os.path.abspath(sys.argv[1]), sys.argv[2:]
    env = dict(os.environ, PATH=bin_dir + os.pathsep + os.environ.get("PATH", ""))
    total = sum(run_page(page, env) for page in pages)
    if total == 0:
        sys.exit("no tutorial command found: the pages have no `sh` block")
    print(f"the tutorials' {total} blocks ran")


if __name__ == "__main__":
    main()
