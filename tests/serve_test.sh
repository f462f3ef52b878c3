#!/usr/bin/env bash
# The virtual cell end to end (docs/virtual-cell.md), loopback only: `hotgauge simulate --serve`
# is a GigE Vision camera on 127.0.0.3 plus an accelerometer stream; `hotgauge grab` records the
# top face from it through Aravis in each frame mode; `hotgauge measure` must give the dimensions
# the offline simulator path gives for the same part within ±0.03 mm. Then: 1 % GVSP packet loss
# is recovered by resend with no profile lost, and a camera killed mid-scan fails that scan
# cleanly while a later scan succeeds once it is back.
#   serve_test.sh HOTGAUGE_BINARY SOURCE_DIR
set -euo pipefail
bin=$1
src=$2
tmp=$(mktemp -d)
addr=127.0.0.3  # its own address: runs beside grab_test's camera on 127.0.0.1
serve_pid=
cleanup() {
  [ -n "$serve_pid" ] && kill "$serve_pid" 2>/dev/null && wait "$serve_pid" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; exit 1; }
py=/usr/bin/python3
free_udp_port() {
  $py -c 'import socket; s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}
seed=3
temp=1000

# serve NAME ARGS...: starts the virtual cell, returns once it says it is serving.
serve() {
  local name=$1
  shift
  "$bin" simulate --serve --address "$addr" --seed "$seed" --temperature "$temp" "$@" \
    > "$tmp/$name.out" 2> "$tmp/$name.err" &
  serve_pid=$!
  for _ in $(seq 1 100); do
    grep -q "^serving virtual camera" "$tmp/$name.out" && return 0
    kill -0 "$serve_pid" 2>/dev/null || fail "virtual cell $name exited: $(cat "$tmp/$name.err")"
    sleep 0.05
  done
  fail "virtual cell $name did not come up"
}
stop_serving() {
  kill "$serve_pid"
  wait "$serve_pid" || true
  serve_pid=
}

# compare JSON_A JSON_B LABEL: every top-face feature measured OK in both, |a − b| ≤ 0.03 mm.
compare() {
  $py - "$1" "$2" "$3" "$tmp/offline.truth/truth.yaml" <<'PY'
import json, sys, yaml
a, b = (json.load(open(p)) for p in sys.argv[1:3])
truth = {f["name"]: f["cold_mm"] for f in yaml.safe_load(open(sys.argv[4]))["features"]}
# The top face's features: those it measures first (a forging's outer diameter lists the side
# scans after it, for its draft when they are there).
top = [f for f in a["features"] if f["faces"][0] == "top" and f["kind"] == "diameter"]
assert len(top) >= 3, "the top face measures at least three features"
live = {f["name"]: f for f in b["features"]}
worst = 0.0
for f in top:
    g = live[f["name"]]
    assert f["verdict"] == "OK" and g["verdict"] == "OK", (f["name"], f["verdict"], g["verdict"], g["reason"])
    d = g["cold_mm"] - f["cold_mm"]
    worst = max(worst, abs(d))
    print(f'{sys.argv[3]}: {f["name"]:<12} offline {f["cold_mm"]:.4f}  live {g["cold_mm"]:.4f}  '
          f'diff {d*1000:+.1f} µm  (truth {truth[f["name"]]:.4f})')
    assert abs(d) <= 0.03, f'{f["name"]}: live differs from offline by {d:.4f} mm'
assert b["match"]["found"], b["match"]
assert b["compensation"], "compensated"
print(f'{sys.argv[3]}: worst |live - offline| = {worst*1000:.1f} µm')
PY
}

# The offline path: the same part (seed, temperature) simulated and measured.
"$bin" simulate --out "$tmp/offline" --faces top --seed "$seed" --temperature "$temp" > /dev/null
"$bin" measure "$tmp/offline" --json > "$tmp/offline.json" 2> /dev/null

validator="$src/../shared/tools/validate-recording"
# check_and_compare MODE: the grabbed recording is valid, its accelerometer record whole, and
# its dimensions those of the offline path.
check_and_compare() {
  local m=$1
  cat "$tmp/$m.grab" "$tmp/$m.out"
  grep -q "(0 gaps, 0 missing)" "$tmp/$m.grab" || fail "$m: accelerometer record has gaps"
  if [ -f "$validator" ]; then
    $py "$validator" "$tmp/$m" > /dev/null || fail "validator rejected the $m recording"
  fi
  "$bin" measure "$tmp/$m" --json > "$tmp/$m.json" 2> /dev/null || true
  compare "$tmp/offline.json" "$tmp/$m.json" "$m" || fail "$m mode dimensions"
}
grab_common=(--camera "$addr" --temperature "$temp" --timeout-ms 500)

# Peaks mode: 10 profiles of 2048 Mono16 peaks per frame, 1 kHz lines, 100 mm/s.
port=$(free_udp_port)
serve peaks --mode peaks --accel-to "127.0.0.1:$port"
"$bin" grab "${grab_common[@]}" --mode peaks --width 2048 --height 10 --pixel-format Mono16 \
  --profiles-per-frame 10 --frame-rate 100 --speed-mm-s 100 --seconds 2.6 \
  --accel "udp://127.0.0.1:$port" --out "$tmp/peaks" > "$tmp/peaks.grab" 2> "$tmp/peaks.grab.err" \
  || fail "peaks grab: $(cat "$tmp/peaks.grab" "$tmp/peaks.grab.err")"
stop_serving
check_and_compare peaks

# Image mode: Mono8 stripe images of sensor rows 320..863 (z ≈ 845..935 mm), 40 frames/s at
# 24 mm/s (0.6 mm profiles), exposure from the temperature table.
port=$(free_udp_port)
serve image --mode image --speed-mm-s 24 --accel-to "127.0.0.1:$port"
"$bin" grab "${grab_common[@]}" --mode image --width 2048 --height 544 --offset-y 320 \
  --pixel-format Mono8 --max-value 255 --exposure-table 20:400,700:200,1000:100,1200:50 \
  --frame-rate 40 --speed-mm-s 24 --seconds 10 --accel "udp://127.0.0.1:$port" \
  --out "$tmp/image" > "$tmp/image.grab" 2> "$tmp/image.grab.err" || fail "image grab: $(cat "$tmp/image.grab" "$tmp/image.grab.err")"
stop_serving
grep -q "exposure 100.0 µs for 1000 °C (table)" "$tmp/image.grab.err" || fail "exposure table not applied"
check_and_compare image

# 1 % of the GVSP packets dropped on the link: resend recovers every one, no profile is lost.
# The quick cell's 512-ray fan: the link carries the same packets per frame count as it does
# for any width, and the device has CPU to spare for resends.
serve lossy --mode peaks --packet-loss 0.01 --quick
"$bin" grab "${grab_common[@]}" --mode peaks --width 512 --height 40 --pixel-format Mono16 \
  --profiles-per-frame 40 --frame-rate 25 --speed-mm-s 100 --seconds 3 --out "$tmp/lossy" \
  > "$tmp/lossy.grab" 2>&1 || fail "lossy grab: $(cat "$tmp/lossy.grab")"
stop_serving
cat "$tmp/lossy.grab" "$tmp/lossy.out"
$py - "$tmp/lossy.grab" "$tmp/lossy.out" "$tmp/lossy" <<'PY' || fail "packet loss not recovered"
import re, sys, numpy as np
grab, served = open(sys.argv[1]).read(), open(sys.argv[2]).read()
num = lambda pattern, text: int(re.search(pattern, text).group(1))
frames = num(r"grabbed top: (\d+) frames", grab)
dropped = num(r"(\d+) dropped on purpose", served)
resent = num(r"(\d+) resent,", served)
served_frames = num(r"served (\d+) frames", served)
assert dropped > 0 and resent > 0, (dropped, resent)
# Every frame the device sent arrived whole, but perhaps the one in flight when the grab stopped.
assert frames >= served_frames - 1, (frames, served_frames)
assert num(r"\((\d+) skipped", served) == 0, "the device fell behind: the check below means nothing"
assert num(r"\((\d+) incomplete", grab) == 0
assert num(r"(\d+) missing frames", grab) == 0
assert num(r"(\d+) missing packets", grab) == 0
t = np.load(f"{sys.argv[3]}/top/profile_times.npy")
assert len(t) == 40 * frames, (len(t), frames)
# No frame missing between the first and the last: frame starts 40 ms apart throughout.
starts = np.diff(t[::40]) * 1e-6
assert np.all(np.abs(starts - 40.0) < 1.0), starts
print(f"lossy link: {dropped} packets dropped, {resent} resent, {frames} frames, {len(t)} profiles, none lost")
PY

# The camera killed mid-scan: the scan fails with the reason; once back, a scan succeeds.
serve killed --mode peaks --quick
"$bin" grab "${grab_common[@]}" --mode peaks --width 512 --height 10 --pixel-format Mono16 \
  --profiles-per-frame 10 --frame-rate 100 --seconds 6 --out "$tmp/killed" \
  > "$tmp/killed.grab" 2> "$tmp/killed.err" &
grab_pid=$!
for _ in $(seq 1 100); do grep -q "grabbing" "$tmp/killed.err" && break; sleep 0.05; done
sleep 0.5
kill -9 "$serve_pid"
wait "$serve_pid" 2>/dev/null || true
serve_pid=
if wait "$grab_pid"; then fail "a scan whose camera died succeeded"; fi
cat "$tmp/killed.err"
grep -q "scan failed after [0-9]* frames: camera lost" "$tmp/killed.err" || fail "no clear reason"
[ ! -e "$tmp/killed" ] || fail "a failed scan left a recording"
serve back --mode peaks --quick
"$bin" grab "${grab_common[@]}" --mode peaks --width 512 --height 10 --pixel-format Mono16 \
  --profiles-per-frame 10 --frame-rate 100 --seconds 1 --out "$tmp/back" > "$tmp/back.grab" \
  2>&1 || fail "scan after the camera came back: $(cat "$tmp/back.grab")"
stop_serving
grep -q "grabbed top: [1-9][0-9]* frames (0 incomplete" "$tmp/back.grab" || fail "no frames after restart"
echo "virtual cell: peaks, image, packet loss, camera killed and back: ok"
