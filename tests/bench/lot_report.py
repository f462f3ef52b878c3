#!/usr/bin/python3
"""Benchmark (issue 19): the lot report and the AQDEF export of a day of 2 000 parts, on one core.

One hub-a part is simulated and measured (`hotgauge simulate`, `hotgauge measure --json`); its
result is written 2 000 times into a day file as the daemon writes it (docs/results.md), each
copy with its own sequence, time, part id and values (σ 0.01 mm, Diameter 3 drifting 5 µm per
100 parts, 1 % of the features not measured). Then, pinned to one core (taskset -c 0), the median
of 5 runs of

    hotgauge report lot DAY --out report.html
    hotgauge export aqdef DAY --out day.dfq

and, for comparison, the same statistics of every feature (mean, s, Cp/Cpk/Pp/Ppk, I-MR limits
from 25 values) in Python with the json module and NumPy, as a quality engineer's script over the
same files would get them, without drawing anything. Target: the report in ≤ 2 s.

    /usr/bin/python3 tests/bench/lot_report.py BUILD [--parts 2000]
"""
import argparse
import copy
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np


def make_day(bin_path, work, parts):
    rec = os.path.join(work, "rec")
    subprocess.run([bin_path, "simulate", "--seed", "3", "--temperature", "1050", "--out", rec],
                   check=True, capture_output=True)
    part = json.loads(subprocess.run([bin_path, "measure", rec, "--json"], check=True,
                                     capture_output=True, text=True).stdout)
    rng = np.random.default_rng(3)
    day = os.path.join(work, "results")
    os.makedirs(day)
    with open(os.path.join(day, "2026-12-04.jsonl"), "w") as out:
        for i in range(parts):
            p = copy.deepcopy(part)
            p["part_id"] = str(240001 + i)
            for f in p["features"]:
                if rng.random() < 0.01:
                    f.update(cold_mm=None, deviation_mm=None, verdict="NOT_MEASURED",
                             reason="not measured: benchmark")
                    continue
                drift = 0.05e-3 * i if f["name"] == "Diameter 3" else 0.0
                f["cold_mm"] = f["nominal_mm"] + rng.normal(0, 0.01) + drift
                f["deviation_mm"] = f["cold_mm"] - f["nominal_mm"]
                lo, hi = f["tolerance_mm"]
                f["verdict"] = "OK" if lo <= f["deviation_mm"] <= hi else "NOK"
            s = 6 * 3600 + i * 10
            line = {"time": f"2026-12-04T{s // 3600:02d}:{s // 60 % 60:02d}:{s % 60:02d}.000+01:00",
                    "time_ns": 0, "sequence": i + 1, "software_version": "bench",
                    "config_hash": "bench", "archived_as": None, "part": p}
            out.write(json.dumps(line) + "\n")
    return day


def median_seconds(cmd, runs=5):
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        subprocess.run(["taskset", "-c", "0", *cmd], check=True, capture_output=True)
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def python_statistics(day):
    values = {}
    for name in sorted(os.listdir(day)):
        with open(os.path.join(day, name)) as f:
            for text in f:
                for feat in json.loads(text)["part"]["features"]:
                    if feat["cold_mm"] is not None and feat["verdict"] in ("OK", "NOK"):
                        values.setdefault(feat["name"], []).append(feat["cold_mm"])
    out = {}
    for name, v in values.items():
        x = np.array(v)
        mr = np.abs(np.diff(x[:25])).mean()
        s_within, s = mr / 1.128, x.std(ddof=1)
        out[name] = (x.mean(), s, 1.0 / (6 * s_within), 1.0 / (6 * s), x[:25].mean() + 3 * s_within)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("build")
    ap.add_argument("--parts", type=int, default=2000)
    a = ap.parse_args()
    bin_path = os.path.join(a.build, "src/app/hotgauge")
    with tempfile.TemporaryDirectory(prefix="hotgauge-lot-bench-") as work:
        day = make_day(bin_path, work, a.parts)
        size = sum(os.path.getsize(os.path.join(day, n)) for n in os.listdir(day))
        report = median_seconds([bin_path, "report", "lot", day, "--out",
                                 os.path.join(work, "report.html")])
        dfq = median_seconds([bin_path, "export", "aqdef", day, "--out",
                              os.path.join(work, "day.dfq")])
        py = median_seconds([sys.executable, "-c", "import sys; sys.path.insert(0, %r); "
                             "import lot_report; lot_report.python_statistics(%r)"
                             % (os.path.dirname(os.path.abspath(__file__)), day)])
        html = os.path.getsize(os.path.join(work, "report.html"))
    print(f"a day of {a.parts} parts ({size / 1e6:.1f} MB of JSON lines), one core, median of 5:")
    print(f"  hotgauge report lot:    {report:.3f} s (HTML {html / 1e6:.2f} MB); target 2 s")
    print(f"  hotgauge export aqdef:  {dfq:.3f} s")
    print(f"  Python json + NumPy, statistics only, no page: {py:.3f} s "
          f"(report / Python = {report / py:.2f})")
    return 0 if report <= 2.0 else 1


if __name__ == "__main__":
    sys.exit(main())
