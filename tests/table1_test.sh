#!/usr/bin/env bash
# The paper's Table 1, reduced to 4 scans: the same part under different blows, Diameter 3
# before and after compensation. Bounds from the compensation issue.
#   table1_test.sh HOTGAUGE_BINARY
set -euo pipefail
out=$("$1" table1 --scans 4 --vibration-scale 2 --json)  # press blows up to ~1 mm
echo "$out"
/usr/bin/python3 - "$out" <<'PY'
import json, sys
t = json.loads(sys.argv[1])
assert len(t["rows"]) == 4
b, c = t["uncompensated"], t["compensated"]
print(f"sd uncompensated {b['sd_mm']:.3f} mm, compensated {c['sd_mm']:.4f} mm; "
      f"max |error| compensated {c['max_abs_error_mm']:.4f} mm")
assert c["sd_mm"] <= 0.01, c
assert c["max_abs_error_mm"] <= 0.03, c
assert b["sd_mm"] >= 0.1, ("vibration must matter uncompensated", b)
assert b["sd_mm"] >= 10 * c["sd_mm"]
PY
