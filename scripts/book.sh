#!/usr/bin/env bash
# The book (book/): its generated pages, then `mdbook build` into the git-ignored book/book.
#
#   scripts/book.sh            generate the pages and build (needs target/debug/mocomp: cargo build)
#   scripts/book.sh tutorial   run every command of the tutorials (scripts/book_tutorial.py)
#
# mdBook is pinned and installed into the git-ignored .tools when it is not there.
set -euo pipefail
cd "$(dirname "$0")/.."
MDBOOK_VERSION=0.4.52
BIN=target/debug
[ -x "$BIN/mocomp" ] || cargo build --locked --bin mocomp
case "${1:-build}" in
  tutorial)
    exec python3 scripts/book_tutorial.py "$BIN" book/src/tutorial/*.md
    ;;
  build)
    if ! [ -x .tools/bin/mdbook ] || [ "$(.tools/bin/mdbook --version)" != "mdbook v$MDBOOK_VERSION" ]; then
      cargo install --locked --quiet mdbook --version "=$MDBOOK_VERSION" --root .tools
    fi
    "$BIN/mocomp" config reference > book/src/reference/configuration.md
    python3 scripts/book_crates.py > book/src/contributing/crates.md
    python3 scripts/book_links.py --self-test
    python3 scripts/book_links.py book/src
    .tools/bin/mdbook build book
    ;;
  *)
    echo "usage: scripts/book.sh [build|tutorial]" >&2
    exit 2
    ;;
esac
