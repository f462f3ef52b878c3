#!/usr/bin/env bash
# make test: every test of both builds, the two cores kept busy (Makefile `test`).
#   1. The real-time tests (ctest label `realtime`: hotgauged, the virtual cell and a PLC, at a
#      third of a core, one at a time) run while the sanitizer build compiles at the lowest
#      priority (nice 19): the compilers take what the line leaves, and the line keeps its pace.
#   2. Every other test of the release build on all cores, the costliest first (COST).
#   3. The sanitizer build's unit tests.
# Every step runs even when an earlier one failed; the exit status is 1 when any did.
# Usage: tests/run_all.sh BUILD BUILD_ASAN JOBS
set -uo pipefail
build=$1 build_asan=$2 jobs=$3
failed=()

realtime_log="$build/realtime-tests.log"
(cd "$build" && ctest --output-on-failure -L realtime) > "$realtime_log" 2>&1 &
realtime=$!
asan_built=1
nice -n 19 cmake --build "$build_asan" -j "$jobs" --target hotgauge_unit_tests ||
  { asan_built=0; failed+=("sanitizer build"); }
wait "$realtime" || failed+=("real-time tests")
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
