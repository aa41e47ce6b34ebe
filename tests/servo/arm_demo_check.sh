#!/bin/sh
# Runs the main demo (examples/arm/demo.sh, the pick-and-place arm) on a
# private backplane and checks its outcome from the job's own lines and
# the monitor's: the object ends resting within the tolerance of its target,
# every phase's switch took effect, every critical module's misses are
# reported (not judged: on a shared virtual machine whole processes stall
# for over a millisecond, which no test here should fail on; make demo
# judges them),
# the monitor printed its figures, and nothing is left behind.
# usage: arm_demo_check.sh SOURCE_ROOT BUILD_DIR
set -u
src=$1 build=$2
dir=$(mktemp -d /dev/shm/chm-armdemo-XXXXXX) || exit 1
bp=$dir/demo.bp
out=$dir/out
clean_up() {
    pkill -9 -f "chimera-rtpu --backplane $bp" 2>/dev/null
    rm -rf "$dir"
}
fail() {
    echo "arm_demo_check: $*"
    cat "$out"
    clean_up
    exit 1
}
trap 'clean_up; exit 1' INT TERM HUP
DEMO_MISSES_ALLOWED=1 CHIMERA_BACKPLANE=$bp DEMO_PLOT=$dir/plot.png DEMO_TOLERANCE=0.01 timeout -k 5 100 \
    sh "$src/examples/arm/demo.sh" "$build" > "$out" 2>&1 || fail "the demo exited with status $?"
cat "$out"

grep -q '^job: OK: object placed within 10.0 mm of its target, ' "$out" ||
    fail "the job did not report success"
# Its figures, checked here too rather than trusted.
err=$(sed -n 's/^job: object at .*, resting; .*placement error \([0-9.]*\) mm.*/\1/p' "$out")
[ -n "$err" ] || fail "no resting object in the job's report"
awk -v e="$err" 'BEGIN { exit !(e <= 10.0) }' || fail "placement error $err mm above 10 mm"
crit=$(grep -cE '^job: [a-z_]+ +RTPU [12] +[0-9]+ cycles  [0-9]+ missed \(critical\)' "$out")
[ "$crit" = 5 ] || fail "$crit of 5 critical modules report their cycles and misses"
[ "$(grep -cE '^job: switch [0-9] \(.*\) effective at T = ' "$out")" = 6 ] || fail "not 6 switches"
[ "$(grep -cE '^  switch [0-9] into ' "$out")" = 6 ] || fail "the monitor did not show the 6 switches"
grep -qE '^ +[0-9]+ s +(approach|pick|move|place|retreat) +q ' "$out" || fail "no figures line from the monitor"
grep -qE '^ +cycles/misses: arm_io [0-9]+/[0-9]+ ' "$out" || fail "no per-module cycles and misses from the monitor"
grep -q '^== chimera rm' "$out" || fail "the system was not removed"
[ -z "$(ls "$dir" | grep -v -e '^out$' -e '^plot.png$')" ] || fail "files left behind: $(ls "$dir")"
rm -rf "$dir"
exit 0
