#!/bin/sh
# Runs examples/errors_open and checks what the README promises: one precise
# error line for the unchecked open, only that task aborted, the RTPU on.
out=$("$1" 2>&1) || { echo "exit status $?"; echo "$out"; exit 1; }
echo "$out"
echo "$out" | grep -q 'task reader .*unix error 2 (No such file or directory) in open("no-such-file")' || exit 1
echo "$out" | grep -q 'the RTPU runs on' || exit 1
echo "$out" | grep -q 'never printed' && exit 1
exit 0
