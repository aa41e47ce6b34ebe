#!/usr/bin/env python3
"""Print the ninja targets the tests of some meson suites need, one per line:
each test's program and what it depends on (make test-asan builds only
these, not the whole tree, in its sanitized build directory).
usage: suite_targets.py BUILD_DIR SUITE..."""
import json
import os
import subprocess
import sys


def introspect(build, what):
    out = subprocess.run(["meson", "introspect", build, what], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    build, suites = sys.argv[1], set(sys.argv[2:])
    files = {t["id"]: t["filename"] for t in introspect(build, "--targets")}
    root = os.path.realpath(build)
    wanted = set()
    for test in introspect(build, "--tests"):
        if not any(s.split(":")[-1] in suites for s in test["suite"]):
            continue
        for dep in test["depends"]:
            wanted.update(files.get(dep, []))
        prog = os.path.realpath(test["cmd"][0])
        if prog.startswith(root + os.sep):
            wanted.add(prog)
    for f in sorted(wanted):
        print(os.path.relpath(os.path.realpath(f), root))


if __name__ == "__main__":
    main()
