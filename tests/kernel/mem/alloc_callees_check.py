#!/usr/bin/env python3
"""Nothing the allocator executes may be preemptible code (mem_text.hpp).

Disassembles the allocator's section (chm_mem_text) of a linked program
and checks every direct branch or call out of it: its target must be in
the section itself, or a PLT entry (which the port carves out of the
preemptible code, port/posix/plt_ranges.cpp). Any other target is code in
the program's own text, which the timer may preempt; a preemption there
inside a malloc that the C library made holding a FILE's lock hands that
lock to the next task (lost stdio lines; on aarch64 the compiler's
out-of-line atomics, __aarch64_cas4_acq and friends, were such targets).
Calls through the GOT (x86-64 -fno-plt) reach shared libraries: not
preemptible, and not visible here as direct targets.

usage: alloc_callees_check.py OBJDUMP PROGRAM
Exit 0 when clean, 1 naming each offending call, 77 (skipped) when the
program has no such section (a sanitizer build serves malloc itself).
"""
import re
import subprocess
import sys

SECTION = "chm_mem_text"
# Called only from a constructor at program start (the allocator's
# pthread_atfork registration, libc_nonshared's wrapper linked into the
# program), before any task exists: nothing can be preempted then.
STARTUP_ONLY = {"__pthread_atfork", "pthread_atfork"}

# Called only with the interrupt mask held (the heap hook's
# irq_restore_no_switch hands a pending tick to the timer before the mask
# drops): the timer never preempts while the mask is held, wherever the
# callee's code lies.
MASK_HELD_ONLY = {"_ZN3chm4port24irq_defer_pending_lockedEv"}
# Mnemonics that transfer control, per objdump's architecture name.
BRANCH = {
    "x86-64": re.compile(r"^(call|jmp|j[a-z]+)$"),
    "aarch64": re.compile(r"^(bl?|b\.[a-z]+|cbn?z|tbn?z)$"),
    "m68k": re.compile(r"^(jsr|jmp|bsr[bwl]?|bra[bwl]?|b[a-z]{2}[bwsl]?|db[a-z]+)$"),
}


def main():
    objdump, program = sys.argv[1], sys.argv[2]
    headers = subprocess.run([objdump, "-h", program], capture_output=True, text=True, check=True).stdout
    sec = None
    for line in headers.splitlines():
        f = line.split()
        if len(f) >= 4 and f[1] == SECTION:
            size, vma = int(f[2], 16), int(f[3], 16)
            sec = (vma, vma + size)
    if sec is None:
        print(f"{program}: no {SECTION} section (sanitized build?): skipped")
        return 77
    dis = subprocess.run([objdump, "-d", "--no-show-raw-insn", "-j", SECTION, program],
                         capture_output=True, text=True, check=True).stdout
    fmt = re.search(r"file format (\S+)", dis)
    arch = next((a for a in BRANCH if fmt and a in fmt.group(1)), None)
    if arch is None:
        print(f"{program}: unknown architecture {fmt.group(1) if fmt else '?'}")
        return 1
    insn = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s+(.*)$")
    target = re.compile(r"\b([0-9a-f]+) <([^>+]+)(\+0x[0-9a-f]+)?>")
    bad, calls = [], 0
    func = "?"
    for line in dis.splitlines():
        fm = re.match(r"^[0-9a-f]+ <([^>]+)>:$", line)
        if fm:
            func = fm.group(1)
            continue
        m = insn.match(line)
        if not m or not BRANCH[arch].match(m.group(2)):
            continue
        operands = m.group(3)
        if "*" in operands.split("#")[0]:
            continue  # indirect (x86-64): through a register or the GOT
        t = target.search(operands)
        if not t:
            continue
        addr, name = int(t.group(1), 16), t.group(2)
        calls += 1
        if sec[0] <= addr < sec[1] or name.endswith("@plt") or name in STARTUP_ONLY or name in MASK_HELD_ONLY:
            continue
        bad.append(f"  {func} -> {name} ({m.group(2)} at 0x{m.group(1)})")
    if bad:
        print(f"{program}: the allocator branches to preemptible code of the program:")
        print("\n".join(sorted(set(bad))))
        return 1
    print(f"{program} ({arch}): {calls} direct branches out of or within {SECTION}, none to preemptible code")
    return 0


if __name__ == "__main__":
    sys.exit(main())
