#!/usr/bin/env bash
# End-to-end through the CLI: simulate a quick part, check it with the independent validator,
# measure it, and check that bad input is a clear error with exit code 1.
#   cli_test.sh HOTGAUGE_BINARY SOURCE_DIR
set -euo pipefail
bin=$1
src=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

"$bin" simulate --quick --out "$tmp/rec" --seed 7 --temperature 900 --part-id T-1 > "$tmp/sim.out"
[ -f "$tmp/rec.truth/part_pose.yaml" ] || fail "no part_pose.yaml beside the truth"

validator="$src/../shared/tools/validate-recording"
if [ -x /usr/bin/python3 ] && [ -f "$validator" ]; then
  /usr/bin/python3 "$validator" "$tmp/rec" || fail "validator rejected the simulated recording"
else
  echo "note: independent validator not found at $validator; skipped"
fi

"$bin" measure "$tmp/rec" --ply "$tmp/cloud.ply" > "$tmp/measure.out"
cat "$tmp/measure.out"
for face in top bottom side1 side2; do
  grep -Eq "^$face +[0-9]+ +512 +[1-9][0-9]* " "$tmp/measure.out" || fail "no summary row for $face"
done
grep -q "part T-1  recipe hub-a" "$tmp/measure.out" || fail "header line missing"
head -c 200 "$tmp/cloud.ply" | grep -q "format binary_little_endian 1.0" || fail "PLY header"

# Bad input: a clear message naming the file, exit code 1, no crash.
set +e
"$bin" measure "$tmp/nothing" 2> "$tmp/err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "measure of a missing recording exited $rc, expected 1"
grep -q "$tmp/nothing/part.yaml" "$tmp/err" || fail "error does not name the file: $(cat "$tmp/err")"
rm "$tmp/rec/top/profile_times.npy"
set +e
"$bin" measure "$tmp/rec" 2> "$tmp/err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "measure of a broken recording exited $rc"
grep -q "profile_times.npy" "$tmp/err" || fail "error does not name the missing array: $(cat "$tmp/err")"
echo "cli test passed"
