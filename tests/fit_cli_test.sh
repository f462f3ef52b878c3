#!/usr/bin/env bash
# `hotgauge fit` against the NIST reference pairs (data/nist-lsq/README.md), a hand-written
# `x y` circle file, and bad input (a clear message naming file:line, exit code 1).
#   fit_cli_test.sh HOTGAUGE_BINARY SOURCE_DIR
set -euo pipefail
bin=$1
src=$2
nist="$src/data/nist-lsq"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

# check.py TYPE JSON_FILE FIT_FILE: compares against the .fit values with tolerances, up to the
# sign of the normal/axis. Circle3d .fit line 7 is the diameter.
cat > "$tmp/check.py" <<'EOF'
import json, sys
kind, out, ref = sys.argv[1], json.load(open(sys.argv[2])), [float(x) for x in open(sys.argv[3]).read().split()]
def check(dev, tol, what):
    if not dev <= tol:
        sys.exit(f"{sys.argv[3]}: {what} off by {dev:.3g} (tolerance {tol:g})")
def dev(a, b, sign=1):
    return max(abs(x - sign * y) for x, y in zip(a, b))
def near(a, b, tol, what):
    check(dev(a, b), tol, what)
def near_unsigned(a, b, tol, what):
    check(min(dev(a, b), dev(a, b, -1)), tol, what + " (up to sign)")
assert out["type"] == kind, out
if kind == "plane":
    near(out["point"], ref[0:3], 1e-8, "point")
    near_unsigned(out["normal"], ref[3:6], 1e-9, "normal")
else:
    near(out["center"], ref[0:3], 1e-8, "centre")
    near_unsigned(out["axis"], ref[3:6], 1e-9, "axis")
    near([out["radius"]], [ref[6] / 2], 1e-8, "radius")
assert out["rms"] >= 0 and out["n_points"] > 0, out
EOF

for ds in "$nist"/Plane/*.ds; do
  "$bin" fit plane "$ds" > "$tmp/out.json" || fail "fit plane $ds exited $?"
  /usr/bin/python3 "$tmp/check.py" plane "$tmp/out.json" "${ds%.ds}.fit" || fail "plane $(basename "$ds")"
done
for ds in "$nist"/Circle3d/*.ds; do
  "$bin" fit circle3d "$ds" > "$tmp/out.json" || fail "fit circle3d $ds exited $?"
  /usr/bin/python3 "$tmp/check.py" circle3d "$tmp/out.json" "${ds%.ds}.fit" || fail "circle3d $(basename "$ds")"
done

# Gander, Golub & Strebel (1994), with comments and blank lines.
printf '# GGS 1994\n1 7\n2 6\n\n5 8  # a comment\n7 7\n9 5\n3 7\n' > "$tmp/ggs.txt"
"$bin" fit circle "$tmp/ggs.txt" > "$tmp/out.json" || fail "fit circle exited $?"
/usr/bin/python3 - "$tmp/out.json" <<'EOF' || fail "GGS circle"
import json, sys
o = json.load(open(sys.argv[1]))
assert o["type"] == "circle" and o["n_points"] == 6, o
assert abs(o["center"][0] - 4.739782) < 1e-6 and abs(o["center"][1] - 2.983533) < 1e-6, o
assert abs(o["radius"] - 4.714226) < 1e-6, o
EOF

# Bad input: exit code 1, the message names the file (and the line for a parse error).
expect_error() {  # expect_error PATTERN ARGS...
  local pattern=$1; shift
  set +e
  "$bin" fit "$@" > "$tmp/stdout" 2> "$tmp/err"; local rc=$?
  set -e
  [ $rc -eq 1 ] || fail "fit $* exited $rc, expected 1"
  grep -qF -- "$pattern" "$tmp/err" || fail "fit $*: error does not name '$pattern': $(cat "$tmp/err")"
  [ ! -s "$tmp/stdout" ] || fail "fit $*: printed to stdout on error"
}
printf '1 2 3\n4 5 6\n7 8 x\n' > "$tmp/bad.txt"
expect_error "$tmp/bad.txt:3:" plane "$tmp/bad.txt"
expect_error "$tmp/nothing.txt" plane "$tmp/nothing.txt"
expect_error "$nist/Plane/pla7.ds:2:" circle "$nist/Plane/pla7.ds"  # circle needs x y
printf '0 0 0\n1 1 1\n2 2 2\n3 3 3\n' > "$tmp/line.txt"
expect_error "$tmp/line.txt" plane "$tmp/line.txt"
expect_error "$tmp/line.txt" circle3d "$tmp/line.txt"
printf '3\n0 0 0\n1 0 0\n' > "$tmp/short.ds"
expect_error "$tmp/short.ds" plane "$tmp/short.ds"
echo "fit cli test passed"
