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

# The JSON interface (docs/measure-output.md): every feature, the documented keys, and the
# values a checker can recompute; with --part-pose from a file elsewhere.
cp "$tmp/rec.truth/part_pose.yaml" "$tmp/pose.yaml"
"$bin" measure "$tmp/rec" --json --part-pose "$tmp/pose.yaml" > "$tmp/m.json"
/usr/bin/python3 - "$tmp/m.json" "$tmp/rec.truth/truth.yaml" <<'PY' || fail "JSON interface"
import json, sys, yaml
m = json.load(open(sys.argv[1]))
truth = {f["name"]: f for f in yaml.safe_load(open(sys.argv[2]))["features"]}
for key in ("part_id", "recipe", "temperature_c", "verdict", "features"):
    assert key in m, key
assert m["part_id"] == "T-1" and m["recipe"] == "hub-a" and m["temperature_c"] == 900
assert m["pose_source"].endswith("pose.yaml"), m["pose_source"]
names = [f["name"] for f in m["features"]]
assert names == list(truth), names
for f in m["features"]:
    for key in ("name", "hot_mm", "cold_mm", "nominal_mm", "deviation_mm", "verdict", "reason",
                "fit_rms_mm", "n_points", "u_mm"):
        assert key in f, (f["name"], key)
    assert f["verdict"] in ("OK", "NOK", "NOT_MEASURED", "DEGRADED")
    if f["hot_mm"] is None:
        assert f["verdict"] == "NOT_MEASURED" and f["reason"], f
        continue
    assert abs(f["deviation_mm"] - (f["cold_mm"] - f["nominal_mm"])) < 1e-9
    # quick mode (1.6 mm rays): coarse, but the numbers must still be the part's
    assert abs(f["hot_mm"] - truth[f["name"]]["hot_mm"]) < 0.5, (f["name"], f["hot_mm"])
print("json ok:", sum(f["hot_mm"] is not None for f in m["features"]), "features measured")
PY

# The default: the part is found in the scans (no truth needed), and measured.
mv "$tmp/rec.truth" "$tmp/truth.moved"
"$bin" measure "$tmp/rec" --json > "$tmp/match.json"
/usr/bin/python3 - "$tmp/match.json" "$tmp/truth.moved/truth.yaml" <<'PY' || fail "matching by default"
import json, sys, yaml
m = json.load(open(sys.argv[1]))
truth = {f["name"]: f for f in yaml.safe_load(open(sys.argv[2]))["features"]}
assert m["pose_source"] == "match", m["pose_source"]
assert m["match"]["found"] and m["match"]["score"] >= 0.8, m["match"]
assert len(m["match"]["world_from_part"]) == 4
for f in m["features"]:
    if f["hot_mm"] is not None:
        assert abs(f["hot_mm"] - truth[f["name"]]["hot_mm"]) < 0.5, (f["name"], f["hot_mm"])
assert sum(f["hot_mm"] is not None for f in m["features"]) >= 10
print("match ok: score", m["match"]["score"])
PY
# --calibration (docs/calibration.md): the cell's geometry replaces the recording's face.yaml.
# The shipped nominal calibration holds the geometry the simulator wrote: the same numbers. A
# travel scale of 1.002 on every face stretches the part along the scan: Diameter 3 reads larger,
# by up to half of 0.2 % (an ellipse stretched along one axis; less, as the given pose is no
# longer on the stretched part's axis). A calibration without one of the recording's faces is
# refused by name.
"$bin" measure "$tmp/rec" --json --part-pose "$tmp/pose.yaml" \
  --calibration "$src/config/calibration.yaml" > "$tmp/cal.json" 2> "$tmp/cal.err" \
  || fail "measure --calibration"
grep -q "method nominal: the faces' geometry is not measured" "$tmp/cal.err" || fail "no nominal warning"
sed 's/travel_scale: 1.0$/travel_scale: 1.002/' "$src/config/calibration.yaml" > "$tmp/scaled.yaml"
"$bin" measure "$tmp/rec" --json --part-pose "$tmp/pose.yaml" --calibration "$tmp/scaled.yaml" \
  > "$tmp/scaled.json" 2> /dev/null || fail "measure --calibration scaled"
/usr/bin/python3 - "$tmp/m.json" "$tmp/cal.json" "$tmp/scaled.json" <<'PY' || fail "--calibration"
import json, sys
plain, cal, scaled = ({f["name"]: f["hot_mm"] for f in json.load(open(p))["features"]}
                      for p in sys.argv[1:4])
assert plain == cal, [(k, plain[k], cal[k]) for k in plain if plain[k] != cal[k]]
d = scaled["Diameter 3"] - plain["Diameter 3"]
expect = plain["Diameter 3"] * 0.001
assert 0.25 * expect < d < 1.5 * expect, (d, expect)
print(f"calibration ok: nominal identical, travel scale 1.002 moves Diameter 3 by {d:.4f} mm")
PY
/usr/bin/python3 - "$src/config/calibration.yaml" "$tmp/noside2.yaml" <<'PY'
import sys, yaml
c = yaml.safe_load(open(sys.argv[1]))
c["faces"] = [f for f in c["faces"] if f["name"] != "side2"]
yaml.safe_dump(c, open(sys.argv[2], "w"))
PY
set +e
"$bin" measure "$tmp/rec" --calibration "$tmp/noside2.yaml" 2> "$tmp/err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "a calibration without side2 exited $rc"
grep -q "noside2.yaml: no face 'side2' (the recording has it)" "$tmp/err" || fail "$(cat "$tmp/err")"
# --pose truth needs the truth: without it, a clear error.
set +e
"$bin" measure "$tmp/rec" --pose truth 2> "$tmp/err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "--pose truth without a truth exited $rc"
grep -q "part_pose.yaml not found" "$tmp/err" || fail "--pose truth error: $(cat "$tmp/err")"
mv "$tmp/truth.moved" "$tmp/rec.truth"
"$bin" measure "$tmp/rec" --pose truth --json > "$tmp/truth.json"
grep -q '"pose_source":"truth ' "$tmp/truth.json" || fail "--pose truth not used"

# Bad input: a clear message naming the file, exit code 1, no crash.
set +e
"$bin" measure "$tmp/nothing" 2> "$tmp/err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "measure of a missing recording exited $rc, expected 1"
grep -q "$tmp/nothing/part.yaml" "$tmp/err" || fail "error does not name the file: $(cat "$tmp/err")"
printf 'world_from_part: [[1,0,0,0],[0,1,0,0],[0,0,2,0],[0,0,0,1]]\n' > "$tmp/bad_pose.yaml"
set +e
"$bin" measure "$tmp/rec" --part-pose "$tmp/bad_pose.yaml" 2> "$tmp/err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "measure with a non-rigid pose exited $rc"
grep -q "bad_pose.yaml:1: world_from_part: not a proper rotation" "$tmp/err" || fail "pose error: $(cat "$tmp/err")"
rm "$tmp/rec/top/profile_times.npy"
set +e
"$bin" measure "$tmp/rec" 2> "$tmp/err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "measure of a broken recording exited $rc"
grep -q "profile_times.npy" "$tmp/err" || fail "error does not name the missing array: $(cat "$tmp/err")"
echo "cli test passed"
