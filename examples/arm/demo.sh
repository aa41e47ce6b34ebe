#!/bin/sh
# `make demo`: the pick-and-place arm on the default backplane
# ($CHIMERA_BACKPLANE, else `chimera path`). Two RTPUs are started empty;
# the job program (chimera-arm-job, a host process) reads the system's
# layout (system.toml: variables, modules, RTPUs, rates), takes control of
# the RTPUs, spawns the control modules and switches them live per phase while
# chimera-arm-monitor prints the figures once a second; then the monitor's
# samples become a PNG plot (plot.py, python3-matplotlib), `chimera stop`
# and `chimera rm`. Ctrl-C stops and cleans up too. The simulated arm's
# files live in a directory of their own ($BP.sim), removed at the end.
# Exit status 0 when the object was placed within tolerance of its target
# and no critical deadline was missed (the job says which failed).
#   DEMO_PLOT       where the plot goes (default: arm-demo.png here)
#   DEMO_TOLERANCE  placement tolerance in m (default 0.015)
#   DEMO_SYSTEM     the system file (default: the built system.toml, beside the modules)
#   DEMO_RTPU_OPTIONS  as for the loop demo (default: SCHED_FIFO 50 when allowed)
#
# usage: demo.sh [BUILD_DIR]   (default: build)
set -u
BUILD=${1:-build}
CHIMERA=$BUILD/tools/chimera/chimera
ARM=$BUILD/examples/arm
HERE=$(dirname "$0")
PLOT=${DEMO_PLOT:-arm-demo.png}
. "$HERE/../demo-lib.sh"
demo_need "$CHIMERA" "$BUILD/tools/chimera-rtpu/chimera-rtpu" "$ARM/chimera-arm-job" "$ARM/chimera-arm-monitor" \
    "$ARM/system.toml" "$ARM/arm_io.so" "$ARM/traj.so" "$ARM/gravity.so" "$ARM/joint_pd.so" "$ARM/force_ctl.so" "$ARM/gripper.so"
BP=$("$CHIMERA" path) || exit 1
RTPUS=2
demo_begin
SIMDIR=$BP.sim
CSV=$BP.csv
# demo-lib's clean-up, then the simulation's files and the samples.
arm_cleanup() {
    rc=$?
    if [ -n "${monitor_pid:-}" ]; then kill "$monitor_pid" 2>/dev/null; wait "$monitor_pid" 2>/dev/null; fi
    rm -rf "$SIMDIR" "$CSV"
    (exit "$rc")
    demo_cleanup
}
trap arm_cleanup EXIT
rm -rf "$SIMDIR" && mkdir -m 700 "$SIMDIR" || exit 1
export CHIMERA_SIM_DIR="$SIMDIR"

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
"$CHIMERA" start --rtpus 2 $options || exit 1
demo_logs

echo
echo "== chimera-arm-monitor (figures once a second) and chimera-arm-job (the phases and switches)"
SYSTEM=${DEMO_SYSTEM:-$ARM/system.toml}
"$ARM/chimera-arm-monitor" --system "$SYSTEM" --seconds 90 --csv "$CSV" &
monitor_pid=$!
"$ARM/chimera-arm-job" --system "$SYSTEM" --tolerance "${DEMO_TOLERANCE:-0.015}"
job_rc=$?
# The monitor ends when the job publishes its end; a job that failed
# before it could must not leave the monitor waiting: 3 s, then it goes.
n=0
while kill -0 "$monitor_pid" 2>/dev/null && [ "$n" -lt 30 ]; do sleep 0.1; n=$((n + 1)); done
kill "$monitor_pid" 2>/dev/null
wait "$monitor_pid"
monitor_rc=$?
monitor_pid=
demo_logs
echo
# The first python3 with matplotlib (a python3 first in PATH, e.g. a
# pyenv one, may lack Debian's python3-matplotlib).
py=
for p in python3 /usr/bin/python3; do
    if "$p" -c 'import matplotlib' 2>/dev/null; then py=$p; break; fi
done
if [ -s "$CSV" ]; then
    if [ -n "$py" ]; then
        "$py" "$HERE/plot.py" "$CSV" "$PLOT" && echo "== plot of the joints and the contact force: $PLOT"
    else
        echo "== no plot made: python3-matplotlib is not installed (apt-get install python3-matplotlib)"
    fi
fi
[ "$monitor_rc" = 0 ] || echo "demo: the monitor ended with status $monitor_rc" >&2
[ "$job_rc" = 0 ] && [ "$monitor_rc" = 0 ]
