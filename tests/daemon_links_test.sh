#!/usr/bin/env bash
# The daemon never links the simulator or the virtual cell (docs/architecture.md): hotgauged
# holds no symbol of hotgauge::sim or hotgauge::vcell, and it does hold calib's (its geometry
# comes from the calibration). The tool `hotgauge` holds vcell's, so the check can tell.
#   daemon_links_test.sh HOTGAUGED HOTGAUGE
set -euo pipefail
daemon=$1 tool=$2
count() { nm -C "$1" | grep -c "$2" || true; }
bad=$(count "$daemon" 'hotgauge::\(sim\|vcell\)::')
calib=$(count "$daemon" 'hotgauge::calib::')
probe=$(count "$tool" 'hotgauge::vcell::')
echo "hotgauged: $bad sim/vcell symbols, $calib calib symbols; hotgauge: $probe vcell symbols"
[ "$probe" -gt 0 ] || { echo "the probe found no vcell symbol in hotgauge: check broken"; exit 1; }
[ "$bad" -eq 0 ] || { nm -C "$daemon" | grep 'hotgauge::\(sim\|vcell\)::' | head; exit 1; }
[ "$calib" -gt 0 ] || { echo "hotgauged holds no calib symbol"; exit 1; }
