#!/bin/sh
# `make demo-multi`: a live three-RTPU Chimera system on the default backplane
# ($CHIMERA_BACKPLANE, else `chimera path`: backplane.bp in a
# directory of the user's alone, $XDG_RUNTIME_DIR/chimera or
# /dev/shm/chimera-<uid>), about 15 seconds:
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
. "$(dirname "$0")/../demo-lib.sh"
demo_need "$CHIMERA" "$BUILD/tools/chimera-rtpu/chimera-rtpu" "$MULTI/servo.so" "$MULTI/supervisor.so" \
    "$MULTI/logger.so"
BP=$("$CHIMERA" path) || exit 1
RTPUS=3
demo_begin

echo "== chimera start: 3 RTPUs on $BP"
demo_started=1
"$CHIMERA" start --rtpus 3 --program "1:$MULTI/servo.so" \
    --program "2:$MULTI/supervisor.so:$(cd "$MULTI" && pwd)/logger.so" || exit 1
for round in 1 2 3 4; do
    sleep 3
    echo
    echo "== t = $((round * 3)) s: what the RTPUs said"
    demo_logs
    if [ "$round" = 2 ] || [ "$round" = 4 ]; then
        echo
        echo "== chimera status"
        "$CHIMERA" status
    fi
done
exit 0
