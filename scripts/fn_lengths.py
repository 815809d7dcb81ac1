#!/usr/bin/env python3
"""No function longer than its limit in the crates that hold the loop's core (issue 30).

    python3 scripts/fn_lengths.py [LIMIT]

For every `fn` in crates/mocomp-control/src (tests included), its length from the line of `fn`
to its closing brace at the same indentation (rustfmt's layout). Any longer than LIMIT (120
lines) is printed, longest first, and the exit status is 1.
"""

import glob
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
CRATES = ["mocomp-control"]
FN = re.compile(r"^(\s*)(pub(\([a-z:]+\))? )?(const )?(async )?(unsafe )?fn ([a-z_0-9]+)")


def lengths(path):
    lines = open(path, encoding="utf-8").read().splitlines()
    for i, line in enumerate(lines):
        m = FN.match(line)
        if not m or line.rstrip().endswith(";"):
            continue
        indent = m.group(1)
        for j in range(i, len(lines)):
            if lines[j] == indent + "}" or (j == i and line.rstrip().endswith("}")):
                yield m.group(7), i + 1, j - i + 1
                break


def main():
    limit = int(sys.argv[1]) if len(sys.argv) > 1 else 120
    found = []
    for crate in CRATES:
        src = os.path.join(ROOT, "crates", crate, "src")
        for f in sorted(glob.glob(os.path.join(src, "**", "*.rs"), recursive=True)):
            for name, line, n in lengths(f):
                found.append((n, os.path.relpath(f, ROOT), line, name))
    found.sort(reverse=True)
    long = [x for x in found if x[0] > limit]
    for n, f, line, name in long:
        print(f"{f}:{line}: fn {name} is {n} lines (limit {limit})")
    if found:
        n, f, line, name = found[0]
        print(f"longest: fn {name} ({f}:{line}), {n} lines; {len(found)} functions")
    return 1 if long else 0


if __name__ == "__main__":
    sys.exit(main())
