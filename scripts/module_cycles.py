#!/usr/bin/env python3
"""No import circle among the modules of any crate (issue 30).

    python3 scripts/module_cycles.py

For each crate under crates/, the graph of its top-level modules: an edge from a module to each
other module its code names by a `crate::…` path (comments and `#[cfg(test)]` modules left out,
a module's own submodules counted as itself). Tarjan's strongly connected components; any
component of more than one module is a circle, printed, and the exit status is 1.
"""

import glob
import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def graph(src):
    files = glob.glob(os.path.join(src, "**", "*.rs"), recursive=True)
    tops = {}
    for f in files:
        rel = os.path.relpath(f, src)[:-3].split(os.sep)
        if rel[0] in ("lib", "main") and len(rel) == 1:
            continue
        tops.setdefault(rel[0], []).append(f)
    edges = {}
    for top, fs in tops.items():
        deps = set()
        for f in fs:
            text = open(f, encoding="utf-8").read().split("#[cfg(test)]")[0]
            code = "\n".join(l for l in text.splitlines() if not l.strip().startswith("//"))
            for name in re.findall(r"crate::([a-z_0-9]+)", code):
                if name != top and name in tops:
                    deps.add(name)
        edges[top] = sorted(deps)
    return edges


def circles(edges):
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in edges.get(v, []):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def main():
    bad = 0
    crates = sorted(glob.glob(os.path.join(ROOT, "crates", "*", "src")))
    for src in crates:
        for c in circles(graph(src)):
            name = os.path.basename(os.path.dirname(src))
            print(f"{name}: import circle among {', '.join(c)}")
            bad += 1
    if bad:
        sys.exit(1)
    print(f"no import circle among the modules of {len(crates)} crates")


if __name__ == "__main__":
    main()
