#!/usr/bin/env python3
"""Every public function is documented in its header (include/chimera/):
a comment right above its declaration (or above the group of declarations
it belongs to, with no blank line between); chimera.h includes every
header; and a function that returns a
status (int) names its errors ("Error" in that comment, or "as chm_..."
pointing to the call whose errors it shares, or a status it returns).

usage: api_docs.py INCLUDE_DIR   (exit 1 and a line per finding)"""
import os
import re
import sys

DECL = re.compile(r'^(?:[A-Za-z_][A-Za-z0-9_ ]*?[\s*]+)(chm_[a-z0-9_]+)\s*\(')


def declarations(lines):
    """(line index, name, return type) of each function declaration."""
    out = []
    i = 0
    while i < len(lines):
        line = lines[i]
        m = DECL.match(line)
        if m and not line.startswith((' ', '\t', '#', '/', '*', 'typedef')):
            head = line[:m.start(1)].strip()
            out.append((i, m.group(1), head))
        i += 1
    return out


def comment_above(lines, i):
    """The comment block above line i, skipping the declarations of its group."""
    j = i - 1
    # Declarations of the same group (contiguous, no blank line).
    while j >= 0 and lines[j].strip() and not lines[j].rstrip().endswith('*/'):
        if lines[j].lstrip().startswith(('/*', '*')):
            break
        j -= 1
    if j < 0 or not lines[j].strip():
        return None
    if not lines[j].rstrip().endswith('*/'):
        return None
    k = j
    while k >= 0 and '/*' not in lines[k]:
        k -= 1
    return '\n'.join(lines[k:j + 1])


def main():
    inc = sys.argv[1]
    bad = []
    for name in sorted(os.listdir(inc)):
        if not name.endswith('.h'):
            continue
        lines = open(os.path.join(inc, name)).read().split('\n')
        for i, fn, ret in declarations(lines):
            c = comment_above(lines, i)
            where = '%s:%d: %s' % (name, i + 1, fn)
            if c is None:
                bad.append(where + ': no comment above its declaration')
                continue
            status = re.search(r'\bint\b', ret) and 'const' not in ret
            if status and not re.search(r'Error|errors of|as chm_|-E[A-Z]+|[Nn]ever fail|Returns', c):
                bad.append(where + ': returns a status but its comment names no errors')
    # chimera.h includes every public header.
    umbrella = open(os.path.join(inc, 'chimera.h')).read()
    for name in sorted(os.listdir(inc)):
        if name.endswith('.h') and name != 'chimera.h' and '"chimera/%s"' % name not in umbrella:
            bad.append('chimera.h: does not include chimera/%s' % name)
    for b in bad:
        print(b)
    print('%d finding(s)' % len(bad))
    return 1 if bad else 0


if __name__ == '__main__':
    sys.exit(main())
