#!/usr/bin/env python3
"""Every relative link in the project's markdown files resolves: the file exists and, for a link to
a .md file with #anchor, a heading of that file gives that anchor (GitHub's rule: lower case,
punctuation dropped, spaces to hyphens). Links inside fenced code blocks and to URLs are skipped.

    check_md_links.py SOURCE_DIR        (CTest docs_links; exit 1 and one line per broken link)
"""
import os
import re
import sys

SKIP_DIRS = {".git", "node_modules"}


def strip_code(text):
    return re.sub(r"```.*?```", "", text, flags=re.S)


def anchors(path):
    out = set()
    with open(path, encoding="utf-8") as f:
        text = strip_code(f.read())
    for line in text.splitlines():
        m = re.match(r"^#+\s+(.*)", line)
        if m:
            title = m.group(1).strip().lower()
            out.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return out


def markdown_files(root):
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [d for d in dirnames if d not in SKIP_DIRS and not d.startswith("build")]
        for name in filenames:
            if name.endswith(".md"):
                yield os.path.join(dirpath, name)


def broken_links(path):
    with open(path, encoding="utf-8") as f:
        text = strip_code(f.read())
    for m in re.finditer(r"\]\(([^)\s]+)\)", text):
        link = m.group(1)
        if re.match(r"^[a-z][a-z0-9+.-]*:", link):
            continue
        target, _, fragment = link.partition("#")
        resolved = os.path.normpath(os.path.join(os.path.dirname(path), target)) if target else path
        if not os.path.exists(resolved):
            yield link, "no such file"
        elif fragment and resolved.endswith(".md") and fragment not in anchors(resolved):
            yield link, "no heading gives #" + fragment


def main(argv):
    if len(argv) != 1:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    root, bad, files = argv[0], 0, 0
    for path in sorted(markdown_files(root)):
        files += 1
        for link, why in broken_links(path):
            print("%s: %s (%s)" % (os.path.relpath(path, root), link, why))
            bad += 1
    print("%d markdown files, %d broken links" % (files, bad))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
