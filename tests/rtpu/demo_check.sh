#!/bin/sh
# Runs the README's main job (examples/loop/demo.sh) for 3 s on a private
# backplane and checks what it promises: the loop closes across the two
# RTPUs, every sample the sensor sent reached the controller at most once,
# every answer is accounted for, every figures record reached the host
# monitor once and in order, and nothing is left behind.
# usage: demo_check.sh SOURCE_ROOT BUILD_DIR
set -u
src=$1 build=$2
dir=$(mktemp -d /dev/shm/chm-demo-XXXXXX) || exit 1
bp=$dir/demo.bp
out=$dir/out
clean_up() {
    pkill -9 -f "chimera-rtpu --backplane $bp" 2>/dev/null
    rm -rf "$dir"
}
fail() {
    echo "demo_check: $*"
    cat "$out"
    clean_up
    exit 1
}
# Killed from outside (meson's timeout): the RTPUs and the files go too.
trap 'clean_up; exit 1' INT TERM HUP
CHIMERA_BACKPLANE=$bp DEMO_SECONDS=3 timeout -k 5 60 sh "$src/examples/loop/demo.sh" "$build" > "$out" 2>&1 ||
    fail "the demo exited with status $?"
cat "$out"

# A figures line per second, and the summary.
[ "$(grep -cE '^ +[0-9]+ s +[0-9]+ ' "$out")" = 3 ] || fail "not one figures line per second"
grep -qE '^records: cycles [0-9]+\.\.[0-9]+, each received once and in order' "$out" ||
    fail "the monitor did not receive every record once and in order"

# The counts the two shutdown hooks printed.
num() { sed -n "s/.*$1: shutdown hook:.* \([0-9][0-9]*\) $2.*/\1/p" "$out"; }
sent=$(num sensor 'samples sent') s_answered=$(num sensor 'answered') lost=$(num sensor 'answers lost')
received=$(num controller 'samples received') c_answered=$(num controller 'answered')
for v in sent s_answered lost received c_answered; do
    eval "[ -n \"\$$v\" ]" || fail "no count '$v' in the shutdown hooks' lines"
done
[ "$s_answered" -gt 0 ] || fail "no answer reached the sensor"
# The stop may come while the sensor waits for one answer: that sample is
# neither answered nor lost yet.
pending=$((sent - s_answered - lost))
[ "$pending" = 0 ] || [ "$pending" = 1 ] ||
    fail "sensor: $s_answered answered + $lost lost, $sent sent (more than one sample unaccounted for)"
[ "$received" -le "$sent" ] || fail "the controller received $received samples of $sent sent (duplicates)"
[ "$c_answered" -le "$received" ] || fail "the controller answered $c_answered of $received samples"
[ "$s_answered" -le "$c_answered" ] || fail "the sensor took $s_answered answers of $c_answered sent"

[ -z "$(ls "$dir" | grep -v '^out$')" ] || fail "files left behind: $(ls "$dir")"
rm -rf "$dir"
exit 0
