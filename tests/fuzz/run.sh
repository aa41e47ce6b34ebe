#!/bin/sh
# Run one libFuzzer harness for a set time, starting from its seed corpus
# and any further input directories (tests/fuzz/regress: inputs that
# crashed the code before issue 15's validation); new inputs go to a
# scratch directory, never into the repository. Prints its executions.
# Exit status: the harness's (0: no crash, hang or sanitizer report).
#   run.sh HARNESS CORPUS_DIR SECONDS [DIR | libFuzzer option]...
# Inside a new user and PID namespace where the system allows one: a
# harness reads pids from mutated files, and there it can reach no
# process but its own.
set -eu
bin=$1 corpus=$2 secs=$3
shift 3
work=$(mktemp -d "${TMPDIR:-/tmp}/chm-fuzz-run-XXXXXX")
trap 'rm -rf "$work"' EXIT INT TERM
mkdir "$work/new" "$work/artifacts"
ns=""
if command -v unshare >/dev/null 2>&1 && unshare -Urp --fork --mount-proc true 2>/dev/null; then
    ns="unshare -Urp --fork --mount-proc"
fi
status=0
ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}" \
UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}" \
    $ns "$bin" -max_total_time="$secs" -timeout=20 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$work/artifacts/" "$work/new" "$corpus" "$@" >"$work/log" 2>&1 || status=$?
runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$work/log")
rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$work/log")
echo "$(basename "$bin"): ${runs:-?} executions in ${secs} s (${rate:-?}/s), exit status $status"
if [ "$status" != 0 ]; then
    tail -n 60 "$work/log"
    ls "$work/artifacts" 2>/dev/null | sed 's/^/artifact: /'
    # Keep what reproduces it beside the build, outside the scratch dir.
    keep="${FUZZ_ARTIFACTS:-$PWD/fuzz-artifacts}"
    mkdir -p "$keep" && cp "$work/artifacts/"* "$keep/" 2>/dev/null || true
fi
exit "$status"
