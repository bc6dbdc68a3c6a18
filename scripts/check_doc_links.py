#!/usr/bin/env python3
"""Fails on a broken relative link in the project's Markdown (README.md, docs/, bench/results/),
and on a README.md that outgrows a front page (README_LIMIT characters).

A link [text](path#anchor) or image ![alt](path) that is not a URL must name a file or folder that
exists, relative to the page; an anchor into a Markdown page (or #anchor alone) must name one of
its headings as GitHub spells them. Links inside code (fenced blocks, `inline`) are not links.
Prints every broken link as FILE:LINE: problem, and exits 1 when there is one.

usage: check_doc_links.py [ROOT]   (default: the repository holding this script)
"""

import os
import re
import sys

LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
FENCE = re.compile(r"^\s*(```|~~~)")
HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
# The README is the front page: what Duplex is, the two commands, a tour, links. Detail belongs in docs/.
README_LIMIT = 12000


def pages(root):
    """The Markdown files checked, relative to root."""
    found = ["README.md"] if os.path.isfile(os.path.join(root, "README.md")) else []
    for top in ("docs", os.path.join("bench", "results")):
        for folder, _, files in os.walk(os.path.join(root, top)):
            found += [os.path.relpath(os.path.join(folder, f), root) for f in files if f.endswith(".md")]
    return sorted(found)


def prose_lines(text):
    """(line number, line) outside fenced code blocks."""
    fenced = None
    for number, line in enumerate(text.splitlines(), 1):
        m = FENCE.match(line)
        if m:
            if fenced is None:
                fenced = m.group(1)
            elif m.group(1) == fenced:
                fenced = None
            continue
        if fenced is None:
            yield number, line


def slug(heading):
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"`([^`]*)`", r"\1", heading)
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    text = text.strip().lower()
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path, cache={}):
    if path not in cache:
        seen = {}
        names = set()
        with open(path, encoding="utf-8") as f:
            for _, line in prose_lines(f.read()):
                m = HEADING.match(line)
                if not m:
                    continue
                base = slug(m.group(2))
                n = seen.get(base, 0)
                seen[base] = n + 1
                names.add(base if n == 0 else "%s-%d" % (base, n))
        cache[path] = names
    return cache[path]


def check(root, page):
    problems = []
    path = os.path.join(root, page)
    with open(path, encoding="utf-8") as f:
        text = f.read()
    for number, line in prose_lines(text):
        for m in LINK.finditer(INLINE_CODE.sub("", line)):
            target = m.group(1)
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.I):
                continue  # a URL (http:, https:, mailto:)
            file_part, _, anchor = target.partition("#")
            resolved = os.path.normpath(os.path.join(os.path.dirname(path), file_part)) if file_part else path
            if not os.path.exists(resolved):
                problems.append("%s:%d: %s: no such file" % (page, number, target))
            elif anchor and resolved.endswith(".md") and anchor not in anchors(resolved):
                problems.append("%s:%d: %s: no heading with anchor #%s" % (page, number, target, anchor))
    return problems


def main():
    root = sys.argv[1] if len(sys.argv) > 1 else os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    root = os.path.abspath(root)
    checked = pages(root)
    problems = [p for page in checked for p in check(root, page)]
    readme = os.path.join(root, "README.md")
    if os.path.isfile(readme):
        size = len(open(readme, encoding="utf-8").read())
        if size > README_LIMIT:
            problems.append("README.md: %d characters, more than %d: move detail to docs/" % (size, README_LIMIT))
    for p in problems:
        print(p)
    print("check_doc_links: %d pages, %d broken links" % (len(checked), len(problems)), file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
