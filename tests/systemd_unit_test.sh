#!/usr/bin/env bash
# The systemd unit's hardening (issue 8): `systemd-analyze security --offline=yes` must rate
# config/hotgauged.service at an exposure of 2.0 or less, and the unit must verify.
#   systemd_unit_test.sh SOURCE_DIR
set -euo pipefail
src=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cp "$src/config/hotgauged.service" "$tmp/"
cd "$tmp"
out=$(systemd-analyze security --offline=yes hotgauged.service 2>&1)
level=$(printf '%s\n' "$out" | sed -n 's/.*Overall exposure level for hotgauged.service: \([0-9.]*\).*/\1/p')
[ -n "$level" ] || { echo "FAIL: no exposure level in: $out"; exit 1; }
echo "exposure level: $level"
awk -v l="$level" 'BEGIN { exit !(l <= 2.0) }' || { echo "FAIL: exposure $level > 2.0"; printf '%s\n' "$out" | grep '✗'; exit 1; }
grep -q '^Type=notify$' hotgauged.service || { echo "FAIL: not Type=notify"; exit 1; }
grep -q '^WatchdogSec=' hotgauged.service || { echo "FAIL: no watchdog"; exit 1; }
