#!/usr/bin/env bash
# make test: every test of both builds, the two cores kept busy (Makefile `test`).
#   1. The real-time tests (ctest label `realtime`: hotgauged, the virtual cell and a PLC, at a
#      third of a core, one at a time) run while the sanitizer build compiles at the lowest
#      priority (nice 19): the compilers take what the line leaves, and the line keeps its pace.
#   2. Every other test of the release build on all cores, the costliest first (COST).
#   3. The sanitizer build's unit tests.
# Every step runs even when an earlier one failed; the exit status is 1 when any did. The
# real-time tests' output is in BUILD/realtime-tests.log (the second ctest run rewrites
# Testing/Temporary/LastTestsFailed.log: `ctest --rerun-failed` knows only its own failures).
# Usage: tests/run_all.sh BUILD BUILD_ASAN JOBS
set -uo pipefail
build=$1 build_asan=$2 jobs=$3
failed=()

# In its own process group (setsid), so that Ctrl-C or a killed make stops it with everything it
# started (hotgauged, the virtual cell, the PLC scripts), not only this script.
realtime_log="$build/realtime-tests.log"
setsid bash -c 'cd "$1" && exec ctest --output-on-failure -L realtime' _ "$build" \
  > "$realtime_log" 2>&1 &
realtime=$!
trap 'kill -TERM -- "-$realtime" 2>/dev/null' EXIT
trap 'exit 130' INT TERM
asan_built=1
nice -n 19 cmake --build "$build_asan" -j "$jobs" --target hotgauge_unit_tests ||
  { asan_built=0; failed+=("sanitizer build"); }
wait "$realtime" || failed+=("real-time tests")
trap - EXIT
echo "---- real-time tests (ctest -L realtime, while the sanitizer build compiled) ----"
cat "$realtime_log"

(cd "$build" && ctest --output-on-failure -j "$jobs" -LE realtime) || failed+=("release tests")
if ((asan_built)); then
  (cd "$build_asan" && ctest --output-on-failure -j "$jobs" -L unit) || failed+=("sanitizer tests")
fi

if ((${#failed[@]})); then
  printf 'make test FAILED: %s\n' "$(IFS=,; echo "${failed[*]}")"
  exit 1
fi
echo "make test: all passed"
