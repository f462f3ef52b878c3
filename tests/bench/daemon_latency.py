#!/usr/bin/python3
"""End-to-end latency of hotgauged on the virtual line (docs/benchmarks.md "Daemon latency").

Runs N four-face hub-a parts through the virtual line (tests/virtual_line.py) and reports, per
part, the time from the last profile of the last face to the result being valid in the PLC's
registers, as the daemon measures it (camera timestamp of the last profile → the moment
plc::Server::finish returned), split into:
  - accel wait: the accelerometer record the compensation needs after the last profile
    (accelerometer.margin_s), which no processing can shorten;
  - processing: everything after that (compensation, matching, measurement, results files with
    fdatasync, registers).
The PLC side checks the register: it polls every 2 ms and notes when DONE appears.

Alternative in the same run: the offline tool on the same data, `hotgauge measure REC` on each
part's archived recording (a separate process reading the recording and building the model,
as a line integrator would glue `grab` and `measure`); ratio = its wall time / our processing.

    /usr/bin/python3 daemon_latency.py BUILD_DIR [--parts 5] [--forged]

--forged: the parts as forged (draft, fillets, die shift; `simulate --forged`), whose corners are
fitted as profiles and take their draft from the side scans, the last face among them.
"""
import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
import virtual_line as vl  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("bin_dir")
    ap.add_argument("--parts", type=int, default=5)
    ap.add_argument("--address", default="127.0.0.5")
    ap.add_argument("--forged", action="store_true")
    a = ap.parse_args()
    workdir = tempfile.mkdtemp(prefix="hotgauge-latency-")
    line = vl.Line(a.bin_dir, workdir, a.address, seed=21, archive_every_nth_ok=1,
                   forged=a.forged)
    try:
        line.start()
        plc, conveyor = vl.Plc(line.plc_port), vl.Conveyor(line.axis_port)
        for n in range(1, a.parts + 1):
            conveyor.load(n)
            plc.to_idle()
            plc.trigger(900 + n)
            while plc.state() != vl.BUSY and plc.state() != vl.DONE:
                time.sleep(0.002)
            while plc.state() not in (vl.DONE, vl.FAULT):
                time.sleep(0.002)
            assert plc.state() == vl.DONE, f"part {n} faulted"
            plc.to_idle()
        plc.close()
        conveyor.close()
        line.stop()
        log = open(line.daemon.log_path).read()
        latency = [int(m) for m in re.findall(r"seq \d+ recipe \S+: \S+; (\d+) ms after the last", log)]
        lines = []
        for name in sorted(os.listdir(line.results_dir)):
            if name.endswith(".jsonl"):
                lines += [json.loads(t) for t in open(os.path.join(line.results_dir, name))]
        assert len(latency) == len(lines) == a.parts, (len(latency), len(lines))
        rows, ratios = [], []
        for lat, j in zip(latency, lines):
            st = j["part"]["stage_ms"]
            wait = st.get("accel_wait", 0.0)
            proc = lat - wait
            t0 = time.monotonic()
            subprocess.run([os.path.join(a.bin_dir, "src/app/hotgauge"), "measure",
                            j["archived_as"], "--json"], check=True, stdout=subprocess.DEVNULL,
                           stderr=subprocess.DEVNULL)
            offline = (time.monotonic() - t0) * 1000
            ratios.append(offline / proc)
            rows.append((j["sequence"], lat, wait, proc, st.get("compensate", 0), st.get("match", 0),
                         st.get("measure", 0), offline))
        print(f"{'seq':>4} {'latency ms':>10} {'accel wait':>10} {'processing':>10} "
              f"{'(compensate':>11} {'match':>6} {'measure)':>8} | {'offline measure ms':>18}")
        for r in rows:
            print(f"{r[0]:4d} {r[1]:10.0f} {r[2]:10.0f} {r[3]:10.0f} {r[4]:11.0f} {r[5]:6.0f} "
                  f"{r[6]:8.0f} | {r[7]:18.0f}")
        med = statistics.median
        print(f"\nmedian latency {med(latency):.0f} ms (max {max(latency)}), of which the "
              f"accelerometer margin {med(r[2] for r in rows):.0f} ms and processing "
              f"{med(r[3] for r in rows):.0f} ms (max {max(r[3] for r in rows):.0f})")
        print(f"offline `hotgauge measure` on the same recordings: median {med(r[7] for r in rows):.0f} ms; "
              f"ratio offline / daemon processing: median {med(ratios):.2f}")
        print("target (issue 17): last profile -> registers median <= 600 ms, max <= 700 ms; "
              "processing median <= 60 ms")
    finally:
        line.stop()
        shutil.rmtree(workdir, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
