# Shared by the demos (loop/demo.sh, multi/demo.sh); sourced, not run.
# The caller sets CHIMERA (the chimera command), BP (the backplane path)
# and RTPUS (how many RTPUs it starts), then calls demo_begin. On any exit,
# Ctrl-C included, the system is stopped, the RTPUs' last words shown, the
# file removed, and a process or file left behind is reported (status 1).

demo_need() {  # demo_need FILE...: every file the demo uses was built
    for f in "$@"; do
        [ -e "$f" ] || { echo "demo: $f is missing: build first (make build)" >&2; exit 1; }
    done
}

# Print what each RTPU wrote since the last call, prefixed with its number.
demo_logs() {
    n=1
    while [ "$n" -le "$RTPUS" ]; do
        log="$BP.rtpu$n.log"
        if [ -e "$log" ]; then
            eval "from=\${seen$n:-0}"
            total=$(wc -l < "$log")
            if [ "$total" -gt "$from" ]; then
                tail -n +"$((from + 1))" "$log" | head -n "$((total - from))" | sed "s/^/  [rtpu$n] /"
            fi
            eval "seen$n=$total"
        fi
        n=$((n + 1))
    done
}

demo_cleanup() {
    rc=$?
    trap - INT TERM HUP EXIT
    trap '' PIPE  # a closed output must not stop the clean-up (children inherit this)
    if [ "$demo_started" = 1 ]; then
        echo
        echo "== chimera stop"
        "$CHIMERA" stop --timeout 3 || rc=1
        demo_logs
        echo "== chimera rm"
        "$CHIMERA" rm || rc=1
    fi
    left=$(pgrep -f "chimera-rtpu --backplane $BP" || true)
    if [ -n "$left" ]; then
        echo "demo: RTPU processes left: $left" >&2
        kill -9 $left 2>/dev/null
        rc=1
    fi
    if [ -e "$BP" ]; then
        echo "demo: $BP was left behind" >&2
        rc=1
    fi
    exit "$rc"
}

demo_begin() {
    export CHIMERA_BACKPLANE="$BP"
    # A backplane left by an earlier run goes; a live system is not ours.
    if [ -e "$BP" ]; then
        "$CHIMERA" rm || { echo "demo: a system is running on $BP; stop it first (chimera stop)" >&2; exit 1; }
    fi
    demo_started=0
    trap demo_cleanup EXIT
    trap 'exit 130' INT TERM HUP PIPE
}
