#!/usr/bin/env python3
"""The book's page of crates, from the workspace itself (`cargo metadata`): each crate's job as
its Cargo.toml describes it and the crates it builds on, bottom to top, so the page is every
crate as it is today.

    python3 scripts/book_crates.py > book/src/contributing/crates.md
"""

import json
import subprocess
import sys


def main():
    meta = json.loads(subprocess.check_output(
        ["cargo", "metadata", "--format-version", "1", "--no-deps", "--offline", "--locked"]))
    crates = {p["name"]: p for p in meta["packages"]}
    uses = {
        name: sorted({d["name"] for d in p["dependencies"]
                      if d["name"] in crates and d["kind"] is None})
        for name, p in crates.items()
    }
    # Bottom to top: a crate after every crate it builds on (ties by name).
    order, placed = [], set()
    while len(order) < len(crates):
        ready = sorted(n for n in crates if n not in placed and set(uses[n]) <= placed)
        if not ready:
            sys.exit(f"a cycle among {sorted(set(crates) - placed)}")
        order += ready
        placed |= set(ready)
    out = ["# The crates", "",
           f"The workspace's {len(crates)} crates, bottom to top: none builds on one below it "
           "in this list. Generated from each crate's `Cargo.toml` (its description, its "
           "dependencies) when the book is built; a crate's own documentation (`cargo doc "
           "--open`, its `lib.rs`) says more, and what it does not do under **Limits**.", "",
           "| crate | its job | builds on |", "|---|---|---|"]
    for n in order:
        desc = (crates[n].get("description") or "").replace("|", "\\|")
        on = ", ".join(f"`{u}`" for u in uses[n]) or "—"
        out.append(f"| `{n}` | {desc} | {on} |")
    print("\n".join(out))


if __name__ == "__main__":
    main()
