#!/bin/bash
# Runs the libFuzzer harnesses of a HOTGAUGE_FUZZ build (tests/fuzz/README.md), each for SECONDS
# on a working copy of its corpus, so that the runs add up:
#   - what a run found that adds coverage to tests/fuzz/corpus/<harness> is added to it
#     (libFuzzer's -merge=1; nothing is removed, so regression inputs stay; FUZZ_CORPUS_MAX_KB
#     caps a corpus, smallest new inputs first);
#   - a line per harness is appended to tests/fuzz/ledger.tsv: date, harness, the commit the run
#     was built from (+dirty when the tree had changes, +stale when the binary is older than a
#     source), executions, seconds it ran, findings.
# Commit both after a run. FUZZ_NO_LEDGER=1 leaves the corpus and the ledger alone.
# Exit status 1 when any harness had a finding (crash, failed check, timeout, out of memory); its
# reproducer is in FINDINGS/<harness>/, its log in LOGS/<harness>.log. Replay it in the sanitizer
# build (make build-fuzz): build-fuzz/tests/fuzz/<harness> FILE.
#   tests/fuzz/run.sh BUILD_DIR SECONDS [HARNESS ...]     (default: every harness of the corpus)
# Environment: FUZZ_PARALLEL (harnesses run at once, default 1), FUZZ_FINDINGS (default
# BUILD_DIR/fuzz-findings), FUZZ_LOGS (BUILD_DIR/fuzz-logs), FUZZ_ARGS (more libFuzzer flags).
set -u
here=$(cd "$(dirname "$0")" && pwd)
repo=$(cd "$here/../.." && pwd)
build=$(cd "$1" && pwd)
seconds=$2
shift 2
harnesses=("$@")
if [ ${#harnesses[@]} -eq 0 ]; then
    harnesses=($(ls "$here/corpus"))
fi
findings=${FUZZ_FINDINGS:-$build/fuzz-findings}
logs=${FUZZ_LOGS:-$build/fuzz-logs}
cap_kb=${FUZZ_CORPUS_MAX_KB:-1024}
ledger=$here/ledger.tsv
mkdir -p "$logs"
work=$(mktemp -d "${TMPDIR:-/tmp}/hotgauge-fuzz.XXXXXX")
trap 'rm -rf "$work"' EXIT
commit=$(git -C "$repo" rev-parse --short=12 HEAD 2>/dev/null || echo unknown)
if [ -n "$(git -C "$repo" status --porcelain -- src include tests/fuzz/*.cpp tests/fuzz/*.hpp 2>/dev/null)" ]; then
    commit=$commit+dirty
fi

# One harness: run, then merge its new inputs back. Prints its line of the table to $work/<h>.out.
fuzz_one() {
    local h=$1 bin=$build/tests/fuzz/$1 out=$work/$1.out
    if [ ! -x "$bin" ]; then
        echo "$h: $bin not built" >"$out"
        return 1
    fi
    mkdir -p "$work/$h/run" "$work/$h/merged" "$findings/$h" "$here/corpus/$h"
    cp "$here/corpus/$h/"* "$work/$h/run/" 2>/dev/null
    # A binary older than a source of the project was not built from this commit: its run is
    # recorded as such and does not count (ledger.py).
    local built=$commit
    if [ -n "$(find "$repo/src" "$repo/include" "$here" -name '*.[ch]pp' -newer "$bin" | head -1)" ]; then
        built=$commit+stale
    fi
    local started=$SECONDS
    local flags=()
    [ -f "$here/$h.dict" ] && flags+=(-dict="$here/$h.dict")
    # <harness>.args: that harness's own libFuzzer flags (its -max_len).
    local own=()
    [ -f "$here/$h.args" ] && read -r -a own <"$here/$h.args"
    # -timeout: an input that takes 10 s is a hang; -rss_limit_mb/-malloc_limit_mb: a reader must
    # not need more than this for a file of a few kilobytes.
    "$bin" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=512 \
        -print_final_stats=1 -artifact_prefix="$findings/$h/" "${flags[@]}" "${own[@]}" \
        ${FUZZ_ARGS:-} "$work/$h/run" >"$logs/$h.log" 2>&1
    local rc=$?
    local took=$((SECONDS - started))
    local runs rate result
    runs=$(grep -h 'stat::number_of_executed_units' "$logs/$h.log" | awk '{s += $2} END {print s + 0}')
    rate=$(grep -h 'stat::average_exec_per_sec' "$logs/$h.log" | awk '{s += $2} END {print s + 0}')
    local found=0
    if [ $rc -eq 0 ]; then
        result=ok
    else
        found=1
        local artifact
        artifact=$(grep -ho "Test unit written to .*" "$logs/$h.log" | tail -1 | sed 's/Test unit written to //')
        result="FINDING (exit $rc): ${artifact:-see $logs/$h.log}"
    fi
    if [ -z "${FUZZ_NO_LEDGER:-}" ]; then
        merge_back "$h" "$bin" "${own[@]}" >>"$logs/$h.log" 2>&1
        # Appended as soon as the harness ends (a run stopped later keeps what was done), one
        # writer at a time.
        (
            flock 9
            [ -s "$ledger" ] || printf 'date\tharness\tcommit\texecutions\tseconds\tfindings\n' >"$ledger"
            printf '%s\t%s\t%s\t%s\t%s\t%s\n' "$(date -u +%Y-%m-%dT%H:%M:%SZ)" "$h" "$built" "$runs" \
                "$took" "$found" >>"$ledger"
        ) 9>>"$ledger"
    fi
    printf '%-20s %8s %12s %10s %8s  %s\n' "$h" "$took" "$runs" "$rate" \
        "$(ls "$here/corpus/$h" | wc -l)" "$result" >"$out"
    if [ $rc -ne 0 ]; then
        grep -hE 'ERROR: |FUZZ CHECK FAILED|SUMMARY: |threw |^    #[0-9] ' "$logs/$h.log" | head -12 |
            sed 's/^/    /' >>"$out"
    fi
    return $found
}

# The run's inputs that add coverage to the in-tree corpus (libFuzzer's -merge=1 into a copy of
# it), added to it smallest first up to the cap. Nothing in the corpus is removed.
merge_back() {
    local h=$1 bin=$2
    shift 2
    local corpus=$here/corpus/$h merged=$work/$h/merged
    cp "$corpus"/* "$merged/"
    "$bin" -merge=1 "$@" "$merged" "$work/$h/run" || return 0
    local budget=$((cap_kb * 1024 - $(cat "$corpus"/* | wc -c)))
    local f size
    for f in $(ls -S -r "$merged"); do
        [ -e "$corpus/$f" ] && continue
        size=$(stat -c %s "$merged/$f")
        [ "$size" -gt "$budget" ] && break
        cp "$merged/$f" "$corpus/$f"
        budget=$((budget - size))
    done
}

export -f fuzz_one merge_back
export here repo build seconds findings logs cap_kb work commit ledger

printf '%-20s %8s %12s %10s %8s  %s\n' harness seconds executions exec/s corpus result
printf '%s\n' "${harnesses[@]}" | xargs -P "${FUZZ_PARALLEL:-1}" -I{} bash -c 'fuzz_one {}'
status=$?
for h in "${harnesses[@]}"; do
    cat "$work/$h.out" 2>/dev/null
done
[ $status -eq 0 ] || exit 1
exit 0
