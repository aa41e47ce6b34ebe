#!/bin/sh
# Peer death is visible (issue 15, item 8): runs examples/loop/demo.sh on a
# private backplane, kills RTPU 2 (the controller) with SIGKILL once the
# loop runs, and checks what the user is told: the monitor names the dead
# RTPU and how it ended, `chimera status` does too, the sensor goes to its
# safe output, the summary counts the unanswered cycles, and the demo
# exits non-zero. Nothing may be left behind.
# usage: demo_kill_check.sh SOURCE_ROOT BUILD_DIR
set -u
src=$1 build=$2
dir=$(mktemp -d /dev/shm/chm-demokill-XXXXXX) || exit 1
bp=$dir/demo.bp
out=$dir/out
demo=
clean_up() {
    [ -n "$demo" ] && kill "$demo" 2>/dev/null
    pkill -9 -f "chimera-rtpu --backplane $bp" 2>/dev/null
    rm -rf "$dir"
}
fail() {
    echo "demo_kill_check: $*"
    cat "$out"
    clean_up
    exit 1
}
trap 'clean_up; exit 1' INT TERM HUP
CHIMERA_BACKPLANE=$bp DEMO_SECONDS=4 timeout -k 5 60 sh "$src/examples/loop/demo.sh" "$build" > "$out" 2>&1 &
demo=$!

# Once the monitor printed its first second, the loop runs: kill RTPU 2.
n=0
until grep -qE '^ +1 s +[0-9]+ ' "$out"; do
    n=$((n + 1))
    [ "$n" -le 200 ] || fail "the loop did not start within 20 s"
    sleep 0.1
done
pid=$(pgrep -f "chimera-rtpu --backplane $bp --rtpu 2( |$)") || fail "no RTPU 2 process"
kill -9 "$pid"
# While the demo still runs: chimera status names the dead RTPU.
sleep 0.5
status_out=$(CHIMERA_BACKPLANE=$bp "$build/tools/chimera/chimera" status 2>&1)
wait "$demo"
rc=$?
demo=
cat "$out"
echo "== chimera status after the kill:"
echo "$status_out"

[ "$rc" != 0 ] || fail "the demo exited 0 although its loop broke"
echo "$status_out" | grep -q 'RTPU 2 (rtpu2) died: its process ended without leaving the backplane' ||
    fail "chimera status did not say that RTPU 2 died"
grep -q "chimera-loop-monitor: RTPU 2 (rtpu2, pid $pid) died without leaving the backplane" "$out" ||
    fail "the monitor did not name the dead RTPU"
grep -qE '\[rtpu1\] sensor: cycle [0-9]+: no answer for [0-9]+ cycles, controller RTPU 2 died without leaving the backplane.*safe output' "$out" ||
    fail "the sensor did not go to its safe output naming the dead controller"
grep -q 'SAFE OUTPUT' "$out" || fail "no figures line shows the safe output"
grep -qE '^summary: .*, [1-9][0-9]* unanswered' "$out" || fail "the summary does not count the unanswered cycles"
grep -qE '^the loop broke: 1 RTPU gone' "$out" || fail "the monitor did not say the loop broke"
[ -z "$(ls "$dir" | grep -v '^out$')" ] || fail "files left behind: $(ls "$dir")"
rm -rf "$dir"
exit 0
