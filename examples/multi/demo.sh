#!/bin/sh
# `make demo`: a live three-RTPU Chimera system on the default backplane
# (/dev/shm/chimera-$USER.bp, or $CHIMERA_BACKPLANE), about 15 seconds:
#   RTPU 1  servo.so       1 kHz servo loop; state in global shared memory;
#                          Vs the remote semaphore servo.tick every 100 ms
#   RTPU 2  supervisor.so  10 Hz: watches the servo, moves its set point
#                          (shared memory + spin-lock), starts the logger on
#                          RTPU 3 and signals the servo, both by express mail
#   RTPU 3  logger.so      (started remotely) wakes on servo.tick and
#                          measures the cross-RTPU wake-up
# `chimera status` is shown while it runs; then `chimera stop` (shutdown
# hooks print their figures) and `chimera rm`. Ctrl-C stops and cleans up
# too: no process and no file is left behind.
#
# usage: demo.sh [BUILD_DIR]   (default: build)
set -u
BUILD=${1:-build}
CHIMERA=$BUILD/tools/chimera/chimera
MULTI=$BUILD/examples/multi
for f in "$CHIMERA" "$BUILD/tools/chimera-rtpu/chimera-rtpu" "$MULTI/servo.so" "$MULTI/supervisor.so" \
         "$MULTI/logger.so"; do
    [ -e "$f" ] || { echo "demo: $f is missing: build first (make build)" >&2; exit 1; }
done
BP=${CHIMERA_BACKPLANE:-/dev/shm/chimera-$(id -un).bp}
export CHIMERA_BACKPLANE="$BP"

# A backplane left by an earlier run goes; a live system is not ours.
if [ -e "$BP" ]; then
    "$CHIMERA" rm || { echo "demo: a system is running on $BP; stop it first (chimera stop)" >&2; exit 1; }
fi

started=0
cleanup() {
    trap - INT TERM HUP EXIT
    trap '' PIPE  # a closed output must not stop the clean-up (children inherit this)
    if [ "$started" = 1 ]; then
        echo
        echo "== chimera stop"
        "$CHIMERA" stop --timeout 3
        show_logs
        echo "== chimera rm"
        "$CHIMERA" rm
    fi
    left=$(pgrep -f "chimera-rtpu --backplane $BP" || true)
    [ -z "$left" ] || { echo "demo: RTPU processes left: $left" >&2; kill -9 $left 2>/dev/null; }
    [ ! -e "$BP" ] || echo "demo: $BP was left behind" >&2
}
trap cleanup EXIT
trap 'exit 130' INT TERM HUP PIPE

# Print what each RTPU wrote since the last call, prefixed with its number.
seen1=0 seen2=0 seen3=0
show_logs() {
    for n in 1 2 3; do
        log="$BP.rtpu$n.log"
        [ -e "$log" ] || continue
        eval "from=\$seen$n"
        total=$(wc -l < "$log")
        if [ "$total" -gt "$from" ]; then
            tail -n +"$((from + 1))" "$log" | head -n "$((total - from))" | sed "s/^/  [rtpu$n] /"
        fi
        eval "seen$n=$total"
    done
}

echo "== chimera start: 3 RTPUs on $BP"
started=1
"$CHIMERA" start --rtpus 3 --program "1:$MULTI/servo.so" \
    --program "2:$MULTI/supervisor.so:$(cd "$MULTI" && pwd)/logger.so" || exit 1
for round in 1 2 3 4; do
    sleep 3
    echo
    echo "== t = $((round * 3)) s: what the RTPUs said"
    show_logs
    if [ "$round" = 2 ] || [ "$round" = 4 ]; then
        echo
        echo "== chimera status"
        "$CHIMERA" status
    fi
done
exit 0
