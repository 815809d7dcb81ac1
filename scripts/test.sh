#!/usr/bin/env bash
# The one test command (README.md, .ci/run): installs what the tests need, then runs the format
# check, clippy with -D warnings, the house's rules, every test (interop tests included), and
# builds the book with its tutorials' commands run.
set -euo pipefail
cd "$(dirname "$0")/.."

say() { printf '\n==> %s\n' "$*"; }

# 1. The Python interop peers, pinned, in a git-ignored venv.
PYTHON=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  say "creating .venv with $($PYTHON --version)"
  "$PYTHON" -m venv .venv
fi
say "installing interop peers (requirements-interop.txt)"
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-interop.txt
export MOCOMP_PYTHON="$PWD/.venv/bin/python"
# The Azure Kinect SDK and pyk4a (built against NumPy 1, which the other peers cannot share).
if [ ! -x .venv-k4a/bin/python ]; then
  say "creating .venv-k4a with $($PYTHON --version)"
  "$PYTHON" -m venv .venv-k4a
fi
say "installing the Azure Kinect SDK and pyk4a (requirements-k4a.txt)"
.venv-k4a/bin/python -m pip install --quiet --disable-pip-version-check -r requirements-k4a.txt
export MOCOMP_K4A_PYTHON="$PWD/.venv-k4a/bin/python"

# 2. Debian packages: the C++ OpenIGTLink library and its example sources (interop peer), the
#    browser the console's tests drive (Chromium and its WebDriver), `ip` for the tests'
#    network namespace, and npm.
missing=()
for p in libopenigtlink-dev openigtlink-examples g++ chromium chromium-driver iproute2; do
  dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
# npm, for the BIDS validator below (any npm will do: the lock file pins what it installs).
command -v npm >/dev/null 2>&1 || missing+=(npm)
if [ ${#missing[@]} -gt 0 ]; then
  say "installing Debian packages: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  # Two suites started at once on a fresh machine (a root and a non-root run) both install:
  # the second waits for the first's dpkg lock instead of failing on it.
  $SUDO apt-get -o DPkg::Lock::Timeout=600 update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get -o DPkg::Lock::Timeout=600 install -y -qq "${missing[@]}"
fi

# 3. The BIDS validator (npm), pinned by interop/bids/package-lock.json, in its git-ignored
#    node_modules: the session export's dataset is checked with it.
if [ ! -x interop/bids/node_modules/.bin/bids-validator ]; then
  say "installing bids-validator (interop/bids: npm ci)"
  npm ci --prefix interop/bids --no-audit --no-fund --loglevel=error
fi
export MOCOMP_BIDS_VALIDATOR="$PWD/interop/bids/node_modules/.bin/bids-validator"

# 4. Rust gates. The toolchain comes from rust-toolchain.toml. No incremental build: CI builds
#    each crate once, and the incremental caches would double what the build leaves on disk.
export CARGO_INCREMENTAL=0
say "cargo fmt --check"
cargo fmt --all -- --check
say "cargo clippy (all targets, -D warnings)"
cargo clippy --workspace --all-targets --locked -- -D warnings
say "the house's rules: no import circle among any crate's modules; in every crate no function over 120 lines and no file over 1,000; the loop links no protocol"
python3 scripts/module_cycles.py
python3 scripts/house_rules.py --self-test
python3 scripts/house_rules.py
# Scalps segmented from a T1 and scalps' distance fields are kept between commands (mocomp-app's
# cache_files): the tests keep theirs in a fresh folder, shared by the run, so that they neither
# read nor fill the user's.
MOCOMP_CACHE_DIR="$(mktemp -d)"
export MOCOMP_CACHE_DIR
trap 'rm -rf "$MOCOMP_CACHE_DIR"' EXIT
say "cargo test (workspace): build"
cargo test --workspace --locked --no-run
# 5. The book: its configuration reference (from the program's own template) and its page of
#    crates (from the workspace) generated, then `mdbook build` (mdBook pinned, into .tools).
say "the book: generated pages, mdbook build"
scripts/book.sh build
# The tests run in a network namespace of their own with only loopback (scripts/in-netns.sh): the
# ROS 2 tests speak DDS, which discovers peers by UDP multicast on every interface it finds, and
# no test traffic may leave this machine (every other test uses loopback already).
say "cargo test (workspace), in a network namespace with only loopback"
scripts/in-netns.sh cargo test --workspace --locked --offline
# The tutorials' commands, as a user types them, in such a namespace too.
say "the book's tutorials: every command, in a network namespace with only loopback"
scripts/in-netns.sh scripts/book.sh tutorial
say "all checks passed"
