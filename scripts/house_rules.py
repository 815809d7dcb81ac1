#!/usr/bin/env python3
"""The house's rules, in every crate, as the test command checks them.

    python3 scripts/house_rules.py            check, print the figures, exit 1 on a breach
    python3 scripts/house_rules.py --figures  the lines per crate and the largest files too
    python3 scripts/house_rules.py --self-test

Rules (each crate's `src/`, the code before a file's first `#[cfg(test)]`: tests aside):
- no function longer than 120 lines, from its `fn` line to its closing brace at the same
  indentation (rustfmt's layout);
- no file longer than 1,000 lines;
- the control loop's crate (mocomp-control) depends on no protocol's crate (mocomp-ur,
  mocomp-igtl, mocomp-ros2): it reaches the robot through mocomp-robot's trait.
- the command line (mocomp-cli) parses, calls and prints: what runs (its code apart from the
  clap argument definitions, each option with its help text) at most 2,200 lines, and the
  whole crate at most 3,200 (a ceiling that keeps it from growing; the definitions alone are
  about 1,100 lines for its twenty commands).
Import circles among a crate's modules are scripts/module_cycles.py's.
"""

import glob
import os
import re
import sys
import tomllib

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
FN_LIMIT = 120
FILE_LIMIT = 1000
CLI_CRATE = "mocomp-cli"
CLI_CODE_LIMIT = 2200
CLI_TOTAL_LIMIT = 3200
ARG_DERIVE = re.compile(r"^#\[derive\(.*\b(Args|Parser|Subcommand|ValueEnum)\b")
LOOP_CRATE = "mocomp-control"
PROTOCOL_CRATES = {"mocomp-ur", "mocomp-igtl", "mocomp-ros2"}
FN = re.compile(r"^(\s*)(pub(\([a-z:]+\))? )?(const )?(async )?(unsafe )?fn ([a-z_0-9]+)")


def code_lines(text):
    """The lines before the first `#[cfg(test)]` line (a file's test module comes last)."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.strip() == "#[cfg(test)]":
            return lines[:i]
    return lines


def functions(lines):
    """(name, first line 1-based, length) of each function with a body."""
    for i, line in enumerate(lines):
        m = FN.match(line)
        if not m or line.rstrip().endswith(";"):
            continue
        indent = m.group(1)
        for j in range(i, len(lines)):
            if lines[j] == indent + "}" or (j == i and line.rstrip().endswith("}")):
                yield m.group(7), i + 1, j - i + 1
                break


def measure(root):
    """Lines per crate, every file's length and every function's, tests aside."""
    per_crate, files, fns = {}, [], []
    for crate in sorted(os.listdir(os.path.join(root, "crates"))):
        src = os.path.join(root, "crates", crate, "src")
        total = 0
        for f in sorted(glob.glob(os.path.join(src, "**", "*.rs"), recursive=True)):
            lines = code_lines(open(f, encoding="utf-8").read())
            rel = os.path.relpath(f, root)
            total += len(lines)
            files.append((len(lines), rel))
            fns.extend((n, rel, at, name) for name, at, n in functions(lines))
        per_crate[crate] = total
    return per_crate, sorted(files, reverse=True), sorted(fns, reverse=True)


def argument_definitions(lines):
    """Lines of the clap argument definitions: each item deriving Args, Parser, Subcommand or
    ValueEnum, with its doc comments and attributes, to its closing brace at column 0."""
    n, i = 0, 0
    while i < len(lines):
        if ARG_DERIVE.match(lines[i]):
            start = i
            while start > 0 and lines[start - 1].lstrip().startswith(("///", "#[")):
                start -= 1
            end = i
            while end < len(lines) and lines[end] != "}":
                end += 1
            n += end - start + 1
            i = end + 1
        else:
            i += 1
    return n


def cli_split(root):
    """(all lines, argument-definition lines) of the command line's crate, tests aside."""
    total = defs = 0
    src = os.path.join(root, "crates", CLI_CRATE, "src")
    for f in glob.glob(os.path.join(src, "**", "*.rs"), recursive=True):
        lines = code_lines(open(f, encoding="utf-8").read())
        total += len(lines)
        defs += argument_definitions(lines)
    return total, defs


def protocol_deps(root):
    with open(os.path.join(root, "crates", LOOP_CRATE, "Cargo.toml"), "rb") as f:
        deps = tomllib.load(f).get("dependencies", {})
    return sorted(PROTOCOL_CRATES & set(deps))


def check(root, figures):
    per_crate, files, fns = measure(root)
    breaches = []
    breaches += [f"{f}:{at}: fn {name} is {n} lines (limit {FN_LIMIT})"
                 for n, f, at, name in fns if n > FN_LIMIT]
    breaches += [f"{f}: {n} lines (limit {FILE_LIMIT})" for n, f in files if n > FILE_LIMIT]
    breaches += [f"crates/{LOOP_CRATE}/Cargo.toml: depends on {d}, a protocol's crate"
                 for d in protocol_deps(root)]
    cli_total, cli_defs = cli_split(root)
    if cli_total - cli_defs > CLI_CODE_LIMIT:
        breaches.append(f"crates/{CLI_CRATE}: {cli_total - cli_defs} lines besides its argument "
                        f"definitions (limit {CLI_CODE_LIMIT}): move the work into the crates")
    if cli_total > CLI_TOTAL_LIMIT:
        breaches.append(f"crates/{CLI_CRATE}: {cli_total} lines (limit {CLI_TOTAL_LIMIT})")
    if figures:
        print("lines per crate (src, tests aside):")
        for c, n in sorted(per_crate.items(), key=lambda x: -x[1]):
            print(f"  {c:20s} {n:6d}")
        print(f"  {'total':20s} {sum(per_crate.values()):6d}")
        print("largest files:")
        for n, f in files[:8]:
            print(f"  {n:5d} {f}")
        print("longest functions:")
        for n, f, at, name in fns[:8]:
            print(f"  {n:5d} {name} {f}:{at}")
    for b in breaches:
        print(b)
    n, f, at, name = fns[0]
    print(f"longest fn: {name} ({f}:{at}), {n} lines of {len(fns)} functions; largest file: "
          f"{files[0][1]}, {files[0][0]} lines; {LOOP_CRATE} links no protocol: "
          f"{'no' if protocol_deps(root) else 'yes'}; the command line: {cli_total} lines "
          f"(limit {CLI_TOTAL_LIMIT}), {cli_total - cli_defs} besides its argument definitions "
          f"(limit {CLI_CODE_LIMIT})")
    return 1 if breaches else 0


def self_test():
    """The measure on made-up code: a rule that cannot fail is no rule."""
    body = ["    let x = 1;"] * (FN_LIMIT - 2)
    ok = ["fn fits() {", *body, "}"]
    long = ["pub(crate) fn too_long() {", *body, "    x;", "}"]
    text = "\n".join(ok + long + ["#[cfg(test)]", "mod tests {", *long, "}"])
    got = list(functions(code_lines(text)))
    assert got == [("fits", 1, FN_LIMIT), ("too_long", FN_LIMIT + 1, FN_LIMIT + 1)], got
    cli = ["use clap::Args;", "", "/// A command.", "#[derive(Debug, Args)]",
           "#[command(about)]", "pub struct Cmd {", "    /// An option.", "    #[arg(long)]",
           "    x: u8,", "}", "", "impl Cmd {", "    fn run(&self) {}", "}"]
    assert argument_definitions(cli) == 8, argument_definitions(cli)
    assert argument_definitions(cli[9:]) == 0
    print("self-test: a 120-line function passes, a 121-line one is found, tests are aside; an "
          "argument definition is counted with its docs and attributes, code is not")
    return 0


if __name__ == "__main__":
    if "--self-test" in sys.argv:
        sys.exit(self_test())
    sys.exit(check(ROOT, "--figures" in sys.argv))
