#!/usr/bin/env bash
# `hotgauge model build` and `model info` (docs/model-file.md): from the recipe, from a mesh and
# from a scan; a corrupt, truncated or wrong-version file is a clear error with exit code 1.
#   model_cli_test.sh HOTGAUGE_BINARY SOURCE_DIR
set -euo pipefail
bin=$1
src=$2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

"$bin" model build --recipe "$src/config/parts/hub-a.yaml" --sampling-mm 5 --out "$tmp/hub-a.hgm" \
  > "$tmp/build.out" || fail "model build exited $?"
cat "$tmp/build.out"
[ "$(wc -l < "$tmp/build.out")" -eq 1 ] || fail "model build printed more than one line"
grep -Eq '^model hub-a .*: [1-9][0-9]* samples, [1-9][0-9]* references, [1-9][0-9]* table entries, [0-9.]+ MB, built in [0-9.]+ s' \
  "$tmp/build.out" || fail "model build summary: $(cat "$tmp/build.out")"
[ ! -e "$tmp/hub-a.hgm.tmp" ] || fail "temporary file left behind"

"$bin" model info "$tmp/hub-a.hgm" > "$tmp/info.out" || fail "model info exited $?"
cat "$tmp/info.out"
for pattern in '^format version +2$' '^name +hub-a$' '^source +recipe .*hub-a.yaml$' \
               '^axisymmetric +yes$' '^config +sampling_mm 5, ' '^samples +[1-9]' \
               '^references +[1-9]' '^table +[1-9][0-9]* keys, [1-9][0-9]* entries$'; do
  grep -Eq "$pattern" "$tmp/info.out" || fail "model info lacks /$pattern/"
done

# From a mesh (an ascii PLY box of quads, 20 x 20 x 10 mm) and from a flat scan (ascii PCD).
cat > "$tmp/box.ply" <<'PLY'
ply
format ascii 1.0
element vertex 8
property float x
property float y
property float z
element face 6
property list uchar int vertex_indices
end_header
0 0 0
20 0 0
0 20 0
20 20 0
0 0 10
20 0 10
0 20 10
20 20 10
4 0 2 3 1
4 4 5 7 6
4 0 1 5 4
4 2 6 7 3
4 0 4 6 2
4 1 3 7 5
PLY
"$bin" model build --mesh "$tmp/box.ply" --sampling-mm 2 --out "$tmp/box.hgm" > "$tmp/box.out" \
  || fail "model build --mesh exited $?"
grep -q "^model hub-a (mesh $tmp/box.ply)" "$tmp/box.out" || fail "mesh build: $(cat "$tmp/box.out")"
"$bin" model info "$tmp/box.hgm" | grep -Eq '^dense samples +[1-9]' || fail "mesh model has no dense samples"
{
  printf 'VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 400\nHEIGHT 1\nPOINTS 400\nDATA ascii\n'
  for i in $(seq 0 19); do for j in $(seq 0 19); do echo "$i $j 0"; done; done
} > "$tmp/plane.pcd"
"$bin" model build --scan "$tmp/plane.pcd" --sampling-mm 2 --out "$tmp/plane.hgm" > "$tmp/plane.out" \
  || fail "model build --scan exited $?"
grep -q "^model hub-a (scan $tmp/plane.pcd)" "$tmp/plane.out" || fail "scan build: $(cat "$tmp/plane.out")"

# Bad input: exit code 1, a message naming the file and what is wrong, nothing on stdout.
expect_error() {  # expect_error PATTERN ARGS...
  local pattern=$1; shift
  set +e
  "$bin" model "$@" > "$tmp/stdout" 2> "$tmp/err"; local rc=$?
  set -e
  [ $rc -eq 1 ] || fail "model $* exited $rc, expected 1"
  grep -qF -- "$pattern" "$tmp/err" || fail "model $*: error lacks '$pattern': $(cat "$tmp/err")"
  [ ! -s "$tmp/stdout" ] || fail "model $*: printed to stdout on error"
}
size=$(stat -c %s "$tmp/hub-a.hgm")
cp "$tmp/hub-a.hgm" "$tmp/corrupt.hgm"
printf '\x55' | dd of="$tmp/corrupt.hgm" bs=1 seek=$((size / 2)) conv=notrunc status=none
cmp -s "$tmp/hub-a.hgm" "$tmp/corrupt.hgm" && printf '\xaa' | dd of="$tmp/corrupt.hgm" bs=1 seek=$((size / 2)) conv=notrunc status=none
expect_error "$tmp/corrupt.hgm: corrupt: checksum mismatch" info "$tmp/corrupt.hgm"
head -c $((size - 100)) "$tmp/hub-a.hgm" > "$tmp/short.hgm"
expect_error "$tmp/short.hgm: truncated" info "$tmp/short.hgm"
cp "$tmp/hub-a.hgm" "$tmp/v1.hgm"
printf '\x01' | dd of="$tmp/v1.hgm" bs=1 seek=8 conv=notrunc status=none
expect_error "$tmp/v1.hgm: model format version 1, this build reads 2: rebuild with \`hotgauge model build\`" \
  info "$tmp/v1.hgm"
echo "not a model" > "$tmp/text.hgm"
expect_error "$tmp/text.hgm: not a hotgauge model file" info "$tmp/text.hgm"
expect_error "$tmp/none.hgm: missing" info "$tmp/none.hgm"
expect_error "$tmp/none.stl: no such file" build --mesh "$tmp/none.stl" --out "$tmp/x.hgm"
# Files PCL (PLY, PCD) or VTK (STL) cannot read: our one line naming the file, nothing of
# theirs on stderr (pcl::console silenced, VTK's errors caught by an observer).
echo "not a mesh" > "$tmp/text.ply"
expect_error "$tmp/text.ply: PCL cannot read it as PLY" build --mesh "$tmp/text.ply" --out "$tmp/x.hgm"
[ "$(wc -l < "$tmp/err")" -eq 1 ] || fail "PLY error is more than one line: $(cat "$tmp/err")"
printf 'solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 zero\n' > "$tmp/bad.stl"
expect_error "$tmp/bad.stl: VTK cannot read it as STL: at line 4: Parse error reading STL vertex" \
  build --mesh "$tmp/bad.stl" --out "$tmp/x.hgm"
[ "$(wc -l < "$tmp/err")" -eq 1 ] || fail "STL error is more than one line: $(cat "$tmp/err")"
printf 'VERSION 0.7\nFIELDS x y w\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\nHEIGHT 1\nPOINTS 1\nDATA ascii\n1 2 3\n' \
  > "$tmp/noz.pcd"
expect_error "$tmp/noz.pcd: PCD has no x, y, z fields" build --scan "$tmp/noz.pcd" --out "$tmp/x.hgm"
[ "$(wc -l < "$tmp/err")" -eq 1 ] || fail "PCD error is more than one line: $(cat "$tmp/err")"
expect_error "$tmp/none.yaml" build --recipe "$tmp/none.yaml" --out "$tmp/x.hgm"
expect_error "$tmp/no/dir/x.hgm.tmp: cannot open for writing" build --out "$tmp/no/dir/x.hgm"
[ ! -e "$tmp/x.hgm" ] || fail "a failed build left a model file"

# Bad command line: exit code 2.
set +e
"$bin" model build --mesh a.ply --scan b.pcd --out "$tmp/x.hgm" 2> /dev/null; rc=$?
set -e
[ $rc -eq 2 ] || fail "--mesh with --scan exited $rc, expected 2"
echo "model cli test passed"
