#!/usr/bin/env python3
"""Rewrites the machine's paths out of benchmark results before they are
committed: the checkout's root becomes relative, the shared data folder
becomes $HEADCAST_DATA, scratch folders under /tmp become OUT.
  bench/strip_machine_paths.py --root ROOT [--data DATA] FILE_OR_DIR...
"""
import argparse
import os
import re

TEXT = (".json", ".md", ".csv", ".txt", ".log")


def strip(text, root, data):
    root = root.rstrip("/") + "/"
    if data:
        text = text.replace(os.path.normpath(data), "$HEADCAST_DATA")
    text = text.replace(root + "../shared/data", "$HEADCAST_DATA")
    text = text.replace(root, "")
    return re.sub(r"/tmp/[^/\s\"'`]+", "OUT", text)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--root", required=True)
    p.add_argument("--data", default="")
    p.add_argument("paths", nargs="+")
    a = p.parse_args()
    files = []
    for path in a.paths:
        if os.path.isdir(path):
            for d, _, names in os.walk(path):
                files += [os.path.join(d, n) for n in names if n.endswith(TEXT)]
        else:
            files.append(path)
    for f in files:
        with open(f, encoding="utf-8") as h:
            text = h.read()
        new = strip(text, os.path.abspath(a.root), os.path.abspath(a.data) if a.data else "")
        if new != text:
            with open(f, "w", encoding="utf-8") as h:
                h.write(new)


if __name__ == "__main__":
    main()
