#!/usr/bin/env bash
# hotgauge grab against a real GigE Vision device on loopback: Aravis's stock fake camera
# (arv-fake-gv-camera-0.8, 127.0.0.1). Its test pattern is not a laser stripe, so the check is on
# what must hold for any camera: frames, timestamps, the recording contract, buffer statistics,
# and a clear failure when the camera vanishes mid-scan.
#   grab_test.sh HOTGAUGE_BINARY SOURCE_DIR
set -euo pipefail
bin=$1
src=$2
tmp=$(mktemp -d)
cam_pid=
cleanup() { [ -n "$cam_pid" ] && kill "$cam_pid" 2>/dev/null; rm -rf "$tmp"; }
trap cleanup EXIT
fail() { echo "FAIL: $*"; exit 1; }

start_camera() {
  arv-fake-gv-camera-0.8 -i 127.0.0.1 -s HGTEST > "$tmp/camera.log" 2>&1 &
  cam_pid=$!
  # Ready when it answers: a short grab succeeds (bounded retries, no fixed sleep).
  for _ in $(seq 1 50); do
    if "$bin" grab --camera 127.0.0.1 --seconds 0.2 --out "$tmp/probe" --timeout-ms 200 \
         > /dev/null 2>&1; then rm -rf "$tmp/probe"; return 0; fi
    sleep 0.1
  done
  fail "the fake camera did not come up: $(cat "$tmp/camera.log")"
}

start_camera
"$bin" grab --camera 127.0.0.1 --seconds 1 --frame-rate 50 --width 512 --height 64 \
  --out "$tmp/rec" --part-id GRAB-T1 > "$tmp/grab.out"
cat "$tmp/grab.out"
validator="$src/../shared/tools/validate-recording"
if [ -f "$validator" ]; then
  /usr/bin/python3 "$validator" "$tmp/rec" || fail "validator rejected the grabbed recording"
fi
/usr/bin/python3 - "$tmp/rec" <<'PY' || fail "recording content"
import sys, numpy as np, yaml
d = sys.argv[1]
part = yaml.safe_load(open(f"{d}/part.yaml"))
assert part["part_id"] == "GRAB-T1", part
prof = np.load(f"{d}/top/profiles.npy")
t = np.load(f"{d}/top/profile_times.npy")
pos = np.load(f"{d}/top/profile_positions.npy")
acc = np.load(f"{d}/top/accel.npy")
n = len(t)
assert 35 <= n <= 65, f"{n} profiles from 1 s at 50 Hz"
assert prof.shape == (n, 512, 2), prof.shape
dt = np.diff(t) * 1e-9
assert (dt > 0).all() and abs(np.median(dt) - 0.02) < 0.004, np.median(dt)
assert np.all(np.diff(pos) > 0)
assert acc.shape == (0, 3), acc.shape
print(f"grab ok: {n} profiles, median period {np.median(dt)*1e3:.2f} ms")
PY
grep -q "no accelerometer (K = 0)" "$tmp/grab.out" || fail "K = 0 not said"

# The camera vanishes mid-scan: the scan fails with the reason, nothing is written.
"$bin" grab --camera 127.0.0.1 --seconds 5 --frame-rate 50 --timeout-ms 300 \
  --out "$tmp/lost" > "$tmp/lost.out" 2> "$tmp/lost.err" &
grab_pid=$!
for _ in $(seq 1 50); do grep -q "grabbing" "$tmp/lost.err" && break; sleep 0.1; done
sleep 0.5
kill "$cam_pid"; wait "$cam_pid" 2>/dev/null || true; cam_pid=
set +e
wait "$grab_pid"; rc=$?
set -e
cat "$tmp/lost.err"
[ $rc -eq 1 ] || fail "grab with a vanished camera exited $rc"
grep -q "camera lost" "$tmp/lost.err" || fail "no 'camera lost' reason"
[ ! -e "$tmp/lost" ] || fail "a failed scan left a recording"

# No camera at that address: a clear error.
set +e
"$bin" grab --camera 127.0.0.1 --seconds 0.5 --out "$tmp/none" 2> "$tmp/none.err"; rc=$?
set -e
[ $rc -eq 1 ] || fail "grab without a camera exited $rc"
grep -q "127.0.0.1" "$tmp/none.err" || fail "error does not name the camera: $(cat "$tmp/none.err")"
echo "grab_test passed"
