#!/usr/bin/env python3
"""Check that docs/api-guide.md quotes its examples exactly.

Every ```c block of the guide whose first line is `/* docs/examples/NAME.c */`
must be the text of docs/examples/NAME.c, and every NAME.c in the examples
directory must be quoted. Usage: check_guide.py GUIDE EXAMPLES_DIR
"""
import os
import re
import sys


def main():
    guide, exdir = sys.argv[1], sys.argv[2]
    text = open(guide, encoding="utf-8").read()
    blocks = re.findall(r"^```c\n(.*?)^```$", text, re.S | re.M)
    quoted, errors = set(), []
    for block in blocks:
        m = re.match(r"/\* docs/examples/([A-Za-z0-9_]+\.c) \*/\n", block)
        if not m:
            continue
        name = m.group(1)
        quoted.add(name)
        path = os.path.join(exdir, name)
        if not os.path.exists(path):
            errors.append(f"{name}: quoted in the guide, but there is no {path}")
            continue
        if open(path, encoding="utf-8").read() != block:
            errors.append(f"{name}: the guide's quote differs from {path}")
    for name in sorted(os.listdir(exdir)):
        if name.endswith(".c") and name not in quoted:
            errors.append(f"{name}: not quoted in the guide")
    for e in errors:
        print(e)
    print(f"{len(quoted)} examples quoted, {len(errors)} problem(s)")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
