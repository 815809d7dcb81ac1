#!/usr/bin/env bash
# The quick test command, for working on one crate: its format, clippy with -D warnings, the
# house's rules, and its own tests, in a network namespace with only loopback as the full run's.
#
#   scripts/test-crate.sh CRATE [ARGS FOR cargo test ...]
#   scripts/test-crate.sh mocomp-control
#   scripts/test-crate.sh mocomp-kin --lib ik
#
# The peers an interop test needs come from the full command's installs (scripts/test.sh makes
# .venv, .venv-k4a and the BIDS validator once); without them those tests fail, as they should.
# Before a commit, the full command: scripts/test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
crate=${1:?usage: scripts/test-crate.sh CRATE [cargo test args]}
shift
[ -d "crates/$crate" ] || { echo "no crate crates/$crate" >&2; exit 2; }
say() { printf '\n==> %s\n' "$*"; }
[ -x .venv/bin/python ] && export MOCOMP_PYTHON="$PWD/.venv/bin/python"
[ -x .venv-k4a/bin/python ] && export MOCOMP_K4A_PYTHON="$PWD/.venv-k4a/bin/python"
[ -x interop/bids/node_modules/.bin/bids-validator ] &&
  export MOCOMP_BIDS_VALIDATOR="$PWD/interop/bids/node_modules/.bin/bids-validator"
MOCOMP_CACHE_DIR="$(mktemp -d)"
export MOCOMP_CACHE_DIR
trap 'rm -rf "$MOCOMP_CACHE_DIR"' EXIT
say "cargo fmt --check ($crate)"
cargo fmt -p "$crate" -- --check
say "cargo clippy ($crate, all targets, -D warnings)"
cargo clippy -p "$crate" --all-targets --locked -- -D warnings
say "the house's rules"
python3 scripts/module_cycles.py
python3 scripts/house_rules.py
say "cargo test -p $crate $*, in a network namespace with only loopback"
cargo test -p "$crate" --locked --no-run
scripts/in-netns.sh cargo test -p "$crate" --locked --offline "$@"
say "$crate: passed"
