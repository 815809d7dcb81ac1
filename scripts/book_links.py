#!/usr/bin/env python3
"""Every link between the book's pages leads somewhere: the page exists and, with an anchor, it
has a heading of that anchor (mdBook checks neither). Pages are moved and headings renamed as
the book grows; a link that silently lands at the top of a page, or nowhere, is a wrong page.

    python3 scripts/book_links.py [BOOK_SRC]     exit 1 naming each broken link (file:line)
    python3 scripts/book_links.py --self-test    a broken page and a broken anchor are found
"""
import os
import re
import sys
import tempfile

LINK = re.compile(r"\]\(([^)\s:]+?\.md)(#[^)\s]*)?\)")
HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*#*\s*$")


def anchor(heading):
    """The id mdBook gives a heading: lower case, spaces to hyphens, other punctuation dropped."""
    text = re.sub(r"[`*_]|\[|\]\([^)]*\)", "", heading).strip().lower()
    return "".join(c if c.isalnum() or c in "-_" else "-" if c == " " else "" for c in text)


def pages(src):
    for dirpath, _, files in os.walk(src):
        for name in files:
            if name.endswith(".md"):
                yield os.path.normpath(os.path.join(dirpath, name))


def broken(src):
    anchors = {}
    for page in pages(src):
        with open(page, encoding="utf-8") as f:
            in_code = False
            found = set()
            for line in f:
                if line.startswith("```"):
                    in_code = not in_code
                m = HEADING.match(line)
                if m and not in_code:
                    found.add(anchor(m.group(1)))
            anchors[page] = found
    out = []
    for page in sorted(anchors):
        with open(page, encoding="utf-8") as f:
            for n, line in enumerate(f, 1):
                for m in LINK.finditer(line):
                    target = os.path.normpath(os.path.join(os.path.dirname(page), m.group(1)))
                    where = f"{page}:{n}: {m.group(0)}"
                    if target not in anchors:
                        out.append(f"{where}: no page {target}")
                    elif m.group(2) and m.group(2)[1:] not in anchors[target]:
                        out.append(f"{where}: {target} has no heading #{m.group(2)[1:]}")
    return out


def self_test():
    with tempfile.TemporaryDirectory() as d:
        os.makedirs(os.path.join(d, "guide"))
        with open(os.path.join(d, "a.md"), "w", encoding="utf-8") as f:
            f.write("# A\n\n## The patient's `head`\n\n[ok](guide/b.md#b-and-c)\n")
        with open(os.path.join(d, "guide", "b.md"), "w", encoding="utf-8") as f:
            f.write(
                "# B and C\n\n[ok](../a.md#the-patients-head) [gone](../c.md)\n"
                "[wrong](../a.md#the-head)\n```sh\n# not a heading\n```\n[code](../a.md#not-a-heading)\n"
            )
        found = broken(d)
        assert len(found) == 3, found
        assert "no page" in found[0] and "c.md" in found[0], found
        assert "#the-head" in found[1] and "#not-a-heading" in found[2], found
    print("book_links self-test: a missing page, a missing anchor and a heading in code found")


def main():
    if sys.argv[1:] == ["--self-test"]:
        self_test()
        return 0
    src = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(__file__), "..", "book", "src")
    found = broken(src)
    for line in found:
        print(line, file=sys.stderr)
    if found:
        print(f"{len(found)} broken links in the book", file=sys.stderr)
        return 1
    count = sum(1 for _ in pages(src))
    print(f"book links: every link between its {count} pages leads to its page and heading")
    return 0


if __name__ == "__main__":
    sys.exit(main())
