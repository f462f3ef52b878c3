#!/bin/bash
# Runs the libFuzzer harnesses of a HOTGAUGE_FUZZ build (tests/fuzz/README.md), one after the
# other, each for SECONDS on a scratch copy of its seed corpus (the in-tree corpus never grows),
# and prints executions and exec/s per harness. Exit status 1 when any harness had a finding
# (crash, sanitizer report, failed check, timeout, out of memory); its reproducer is in
# FINDINGS/<harness>/ and its log in LOGS/<harness>.log.
#   tests/fuzz/run.sh BUILD_DIR SECONDS [HARNESS ...]     (default: every harness of the corpus)
# Environment: FUZZ_FINDINGS (default BUILD_DIR/fuzz-findings), FUZZ_LOGS (BUILD_DIR/fuzz-logs),
# FUZZ_ARGS (more libFuzzer flags, e.g. -jobs=2 -workers=2).
set -u
here=$(cd "$(dirname "$0")" && pwd)
build=$(cd "$1" && pwd)
seconds=$2
shift 2
harnesses=("$@")
if [ ${#harnesses[@]} -eq 0 ]; then
    harnesses=($(ls "$here/corpus"))
fi
findings=${FUZZ_FINDINGS:-$build/fuzz-findings}
logs=${FUZZ_LOGS:-$build/fuzz-logs}
mkdir -p "$logs"
scratch=$(mktemp -d "${TMPDIR:-/tmp}/hotgauge-fuzz-corpus.XXXXXX")
# The harnesses' files (fuzz_util.hpp scratch_dir), in memory when there is /dev/shm.
files=$(mktemp -d "$([ -d /dev/shm ] && echo /dev/shm || echo "${TMPDIR:-/tmp}")/hotgauge-fuzz.XXXXXX")
export FUZZ_SCRATCH=$files
trap 'rm -rf "$scratch" "$files"' EXIT

status=0
printf '%-20s %8s %12s %10s  %s\n' harness seconds executions exec/s result
for h in "${harnesses[@]}"; do
    bin=$build/tests/fuzz/$h
    if [ ! -x "$bin" ]; then
        echo "$h: $bin not built" >&2
        status=1
        continue
    fi
    mkdir -p "$scratch/$h" "$findings/$h"
    cp "$here/corpus/$h/"* "$scratch/$h/"
    dict=()
    [ -f "$here/$h.dict" ] && dict=(-dict="$here/$h.dict")
    # <harness>.args: that harness's own libFuzzer flags (e.g. fuzz_modbus's -max_len).
    own=()
    [ -f "$here/$h.args" ] && read -r -a own < "$here/$h.args"
    # -timeout: an input that takes 10 s is a hang; -rss_limit_mb/-malloc_limit_mb: a reader must
    # not need more than this for a file of a few kilobytes.
    "$bin" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=512 \
        -print_final_stats=1 -artifact_prefix="$findings/$h/" "${dict[@]}" "${own[@]}" ${FUZZ_ARGS:-} \
        "$scratch/$h" >"$logs/$h.log" 2>&1
    rc=$?
    runs=$(grep -h 'stat::number_of_executed_units' "$logs/$h.log" | awk '{s += $2} END {print s + 0}')
    rate=$(grep -h 'stat::average_exec_per_sec' "$logs/$h.log" | awk '{s += $2} END {print s + 0}')
    if [ $rc -eq 0 ]; then
        result=ok
    else
        status=1
        artifact=$(grep -ho "Test unit written to .*" "$logs/$h.log" | tail -1 | sed 's/Test unit written to //')
        result="FINDING (exit $rc): ${artifact:-see $logs/$h.log}"
    fi
    printf '%-20s %8s %12s %10s  %s\n' "$h" "$seconds" "$runs" "$rate" "$result"
    if [ $rc -ne 0 ]; then
        grep -hE 'ERROR: |FUZZ CHECK FAILED|SUMMARY: |threw |^    #[0-9] ' "$logs/$h.log" | head -12 | sed 's/^/    /'
    fi
done
exit $status
