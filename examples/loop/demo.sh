#!/bin/sh
# `make demo`: a control loop closed across two RTPUs on the default
# backplane ($CHIMERA_BACKPLANE, else `chimera path`: backplane.bp in a
# directory of the user's alone, $XDG_RUNTIME_DIR/chimera or
# /dev/shm/chimera-<uid>):
#   RTPU 1  sensor.so      1 kHz: samples a simulated mass, sends the sample
#                          (timestamped, 24 bytes) to the controller, waits
#                          for the force it answers and applies it
#   RTPU 2  controller.so  wakes on each sample, answers on a reply queue
#   host    chimera-loop-monitor  prints the figures once a second
# for DEMO_SECONDS (default 10); then `chimera stop` (shutdown hooks print
# their counts) and `chimera rm`. Ctrl-C stops and cleans up too: no
# process and no file is left behind. Exit status 0 when the loop ran.
# The RTPUs run at SCHED_FIFO 50 where the host allows it (root, or an
# rtprio limit); DEMO_RTPU_OPTIONS replaces that choice (e.g. "--pin
# --idle-poll 300", or "" for none; see chimera --help).
#
# usage: demo.sh [BUILD_DIR]   (default: build)
set -u
BUILD=${1:-build}
SECONDS_TO_RUN=${DEMO_SECONDS:-10}
CHIMERA=$BUILD/tools/chimera/chimera
LOOP=$BUILD/examples/loop
MONITOR=$LOOP/chimera-loop-monitor
. "$(dirname "$0")/../demo-lib.sh"
demo_need "$CHIMERA" "$BUILD/tools/chimera-rtpu/chimera-rtpu" "$LOOP/sensor.so" "$LOOP/controller.so" "$MONITOR"
BP=$("$CHIMERA" path) || exit 1
RTPUS=2
demo_begin

if [ -n "${DEMO_RTPU_OPTIONS+set}" ]; then
    options=$DEMO_RTPU_OPTIONS
elif chrt -f 50 true 2>/dev/null; then
    options="--rt-priority 50"
else
    options=""
    echo "(SCHED_FIFO is not allowed here: the RTPUs run as ordinary processes)"
fi
echo "== chimera start --rtpus 2 $options: on $BP"
demo_started=1
# shellcheck disable=SC2086 # the options are words
"$CHIMERA" start --rtpus 2 $options --program "1:$LOOP/sensor.so" --program "2:$LOOP/controller.so" || exit 1
sleep 0.5
demo_logs
echo
echo "== chimera status"
"$CHIMERA" status
echo
echo "== chimera-loop-monitor: the loop's figures, once a second for $SECONDS_TO_RUN s"
echo "   (one-way: sample sent on RTPU 1 -> the controller's task has it on RTPU 2;"
echo "    round trip: sample sent -> the sensor has the answer; lateness: release -> the sensor runs)"
"$MONITOR" --seconds "$SECONDS_TO_RUN"
