#!/usr/bin/env bash
# hotgauge plc serve driven by mbpoll, an external Modbus TCP client, from the shell
# (docs/plc-modbus.md): heartbeat, a full trigger -> BUSY -> DONE -> ack cycle with every hub-a
# feature read back as int32 and float32 and compared with the stand-in cell's documented
# values, both word orders, the holding mirror, a refused trigger, exceptions, FAULT -> reset,
# and config errors that name file:line:key. Loopback, ephemeral ports, bounded polls.
#   plc_mbpoll_test.sh HOTGAUGE_BINARY
set -euo pipefail
bin=$1
recipe=$(dirname "$0")/../config/parts/hub-a.yaml
tmp=$(mktemp -d)
pid=
cleanup() {
  if [ -n "$pid" ]; then kill "$pid" 2>/dev/null || true; wait "$pid" 2>/dev/null || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; [ -f "$tmp/serve.log" ] && tail -20 "$tmp/serve.log"; exit 1; }

# Which feature is in which slot: hub-a's 14, each with its first input register; a recipe that
# is not there is an error naming it.
recipe="$(dirname "$0")/../config/parts/hub-a.yaml"
slots=$("$bin" plc map --recipe "$recipe") || fail "plc map --recipe failed"
[ "$(grep -c '^| [0-9]' <<< "$slots")" = 14 ] || fail "plc map --recipe: not 14 slots: $slots"
grep -q '^| 3 | Diameter 3 | 28–29 / 30–31 / 32 / 33 | 30029 |' <<< "$slots" \
  || fail "plc map --recipe: slot 3 is not Diameter 3 at input 28: $slots"
if "$bin" plc map --recipe "$tmp/none.yaml" > "$tmp/out" 2>&1; then fail "no recipe, exit 0"; fi
grep -q "none.yaml" "$tmp/out" || fail "the error does not name the file: $(cat "$tmp/out")"

start_server() {
  rm -f "$tmp/port"
  "$bin" plc serve --bind 127.0.0.1 --port 0 --port-file "$tmp/port" --busy-ms 2000 "$@" \
    > "$tmp/serve.log" 2>&1 &
  pid=$!
  for _ in $(seq 1 100); do
    [ -s "$tmp/port" ] && break
    kill -0 "$pid" 2>/dev/null || fail "plc serve exited at start"
    sleep 0.05
  done
  [ -s "$tmp/port" ] || fail "no port file"
  port=$(cat "$tmp/port")
}
stop_server() {
  kill -TERM "$pid"
  wait "$pid" || fail "plc serve did not exit cleanly on SIGTERM"
  pid=
  grep -q "stopping:" "$tmp/serve.log" || fail "no shutdown summary"
}

# mbpoll with 0-based references (-0), one poll (-1), 2 s timeout.
mb() { mbpoll -m tcp -a 1 -0 -1 -o 2 -p "$port" "$@"; }
# value of one register: reg REF [TYPE] [extra mbpoll options]
reg() {
  local ref=$1 type=${2:-3}; shift 2 || shift $#
  mb -r "$ref" -t "$type" "$@" 127.0.0.1 | sed -n 's/^\[[0-9]*\]:[[:space:]]*\([-0-9.a-z]*\).*/\1/p'
}
# write holding registers from REF: put REF VALUE...
put() { local ref=$1; shift; mb -r "$ref" -t 4 127.0.0.1 "$@" > /dev/null; }
expect() { [ "$2" = "$3" ] || fail "$1: expected $3, read $2"; }
wait_state() {
  for _ in $(seq 1 100); do
    [ "$(reg 1)" = "$1" ] && return 0
    sleep 0.05
  done
  fail "state did not become $1 (is $(reg 1))"
}

# Expected values: nominal + ((part + slot) mod 5 - 2) * 10 um, per recipe slot (the stand-in cell).
expected() {  # expected PART -> lines "slot um mm"
  /usr/bin/python3 - "$recipe" "$1" <<'PY'
import sys, yaml
recipe, part = yaml.safe_load(open(sys.argv[1])), int(sys.argv[2])
for f in recipe["features"]:
    s = f["slot"]
    lo, hi = (round(x * 1000) for x in f["tolerance_mm"])  # the stand-in stays in tolerance
    um = round(f["nominal_mm"] * 1000) + min(max(((part + s) % 5 - 2) * 10, lo), hi)
    print(s, um, um / 1000)
PY
}

start_server
echo "server on port $port"

# Heartbeat advances on its own.
h1=$(reg 0)
for _ in $(seq 1 50); do [ "$(reg 0)" != "$h1" ] && break; sleep 0.05; done
[ "$(reg 0)" != "$h1" ] || fail "heartbeat stalled at $h1"
expect "state" "$(reg 1)" 1
expect "map version" "$(reg 14)" 4
expect "feature 1 while IDLE" "$(reg 16 3:int -B)" -2147483648

# Trigger: part id 1234 (uint32, big word order), recipe slot 1, all faces; then the command.
put 1 0 1234 1 0
put 0 1
expect "state after trigger" "$(reg 1)" 2
expect "command status" "$(reg 3)" 0
expect "part id echo" "$(reg 6 3:int -B)" 1234
expect "command reads back 0" "$(reg 0 4)" 0
put 0 1  # trigger while BUSY: refused with 101
expect "trigger while busy" "$(reg 3)" 101
expect "still busy" "$(reg 1)" 2
wait_state 3
expect "sequence" "$(reg 5)" 1
expect "overall verdict" "$(reg 11)" 1
expect "feature count" "$(reg 12)" 14
expect "temperature" "$(reg 13)" 10500
n=0
while read -r slot um mm; do
  base=$((16 + 6 * (slot - 1)))
  expect "slot $slot um" "$(reg $base 3:int -B)" "$um"
  f=$(reg $((base + 2)) 3:float -B)
  awk -v a="$f" -v b="$mm" 'BEGIN { d = a - b; exit !(d < 1e-4 && d > -1e-4) }' \
    || fail "slot $slot mm: expected $mm, read $f"
  expect "slot $slot verdict" "$(reg $((base + 4)))" 1
  expect "slot $slot mirror" "$(reg $((100 + base)) 4:int -B)" "$um"
  n=$((n + 1))
done < <(expected 1234)
expect "features checked" "$n" 14
# Slot 1 (138.38 mm) has a non-zero high word: read with the other word order it is wrong.
[ "$(reg 16 3:int)" != "$(reg 16 3:int -B)" ] || fail "word order made no difference"

# Outside the map: exception 02 (mbpoll fails and says so); nothing changes.
if mb -r 123 -t 3 127.0.0.1 > "$tmp/out" 2>&1; then fail "read past the map succeeded"; fi
grep -qi "illegal data address" "$tmp/out" || fail "no exception 02: $(cat "$tmp/out")"
if mb -r 100 -t 4 127.0.0.1 7 > "$tmp/out" 2>&1; then fail "write to the mirror succeeded"; fi
grep -qi "illegal data address" "$tmp/out" || fail "no exception 02: $(cat "$tmp/out")"
expect "still done" "$(reg 1)" 3
expect "sequence unchanged" "$(reg 5)" 1

# Ack: IDLE, nothing shown.
put 0 2
expect "state after ack" "$(reg 1)" 1
expect "feature 1 after ack" "$(reg 16 3:int -B)" -2147483648
expect "verdict after ack" "$(reg 11)" 0

# FAULT: part 999999 = 0x000F423F fails on purpose; a trigger is refused until a reset.
put 1 15 16959 1 0
put 0 1
wait_state 4
expect "error code" "$(reg 2)" 201
put 0 1
expect "trigger in fault" "$(reg 3)" 103
put 0 3
expect "state after reset" "$(reg 1)" 1
expect "error code after reset" "$(reg 2)" 0
stop_server
grep -q "illegal data address" "$tmp/serve.log" || fail "exception 02 not logged"

# Little word order: the same cycle decodes with mbpoll's default (low word first).
start_server --word-order little
put 1 1234 0 1 0  # part id 1234, low word first
put 0 1
wait_state 3
expect "part id echo (little)" "$(reg 6 3:int)" 1234
read -r slot um mm < <(expected 1234)
expect "slot $slot um (little)" "$(reg 16 3:int)" "$um"
put 0 2
stop_server

# Config errors name file:line and the key; the exit code is 1.
printf 'server:\n  bind_address: 127.0.0.1\n  port: 70000\n' > "$tmp/bad.yaml"
if "$bin" plc serve --config "$tmp/bad.yaml" > "$tmp/out" 2>&1; then fail "bad port accepted"; fi
grep -q "bad.yaml:3: server.port: must be in 0..65535" "$tmp/out" || fail "$(cat "$tmp/out")"
printf 'server:\n  prot: 502\n' > "$tmp/bad.yaml"
if "$bin" plc serve --config "$tmp/bad.yaml" > "$tmp/out" 2>&1; then fail "unknown key accepted"; fi
grep -q "bad.yaml:2: server: unknown key 'prot'" "$tmp/out" || fail "$(cat "$tmp/out")"
echo "PASS: mbpoll cycle, both word orders, exceptions, FAULT/reset, config errors"
