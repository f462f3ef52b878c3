#!/usr/bin/python3
"""hotgauge study type1|type3 on a results folder (docs/quality.md): the values are read back
from the JSON lines as the daemon writes them (docs/results.md) and the figures agree with NumPy
on the same values; not-measured values are left out and counted, a retried append counts once,
and bad input is a clear error naming what and where.

    study_cli_test.py HOTGAUGE_BINARY
"""
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np


def line(seq, part_id, features):
    return json.dumps({"time": f"2026-12-04T08:00:{seq % 60:02d}.000+01:00", "time_ns": seq,
                       "sequence": seq, "software_version": "test", "config_hash": "x",
                       "archived_as": None,
                       "part": {"part_id": part_id, "recipe": "hub-a", "verdict": "OK",
                                "features": [{"name": n, "cold_mm": v, "nominal_mm": 48.3,
                                              "tolerance_mm": [-0.3, 0.3],
                                              "verdict": "OK" if v is not None else "NOT_MEASURED"}
                                             for n, v in features.items()]}})


def run(binary, *args, ok=True):
    r = subprocess.run([binary, "study", *args], capture_output=True, text=True)
    if ok and r.returncode != 0:
        sys.exit(f"FAIL: study {' '.join(args)}: exit {r.returncode}: {r.stderr}")
    if not ok and r.returncode == 0:
        sys.exit(f"FAIL: study {' '.join(args)} should have failed: {r.stdout}")
    return r


def close(ours, theirs, what):
    if not math.isclose(ours, theirs, rel_tol=1e-9, abs_tol=1e-12):
        sys.exit(f"FAIL: {what}: {ours} != {theirs}")


def main():
    binary = sys.argv[1]
    rng = np.random.default_rng(4)
    with tempfile.TemporaryDirectory() as tmp:
        res = os.path.join(tmp, "results")
        os.mkdir(res)
        # Type 1: the master M-1 measured 30 times over two days, one of them not measured,
        # one line appended twice (a retried append after a full disk), other parts between.
        ref = rng.normal(48.3, 0.002, 30)
        seq, days = 0, [[], []]
        for i, v in enumerate(ref):
            seq += 1
            days[i // 15].append(line(seq, "M-1", {"Height 2": float(v), "Diameter 3": 69.5}))
            if i == 7:
                days[0].append(days[0][-1])
            seq += 1
            days[i // 15].append(line(seq, f"P-{seq}", {"Height 2": 48.4}))
        seq += 1
        days[1].append(line(seq, "M-1", {"Height 2": None}))
        # Type 3: 5 parts x 3 repeats of Diameter 3 on a third day.
        parts = {f"Q-{k}": list(69.5 + d + rng.normal(0, 0.003, 3))
                 for k, d in enumerate(rng.normal(0, 0.05, 5))}
        day3 = []
        for rep in range(3):
            for pid, x in parts.items():
                seq += 1
                day3.append(line(seq, pid, {"Diameter 3": float(x[rep])}))
        for name, lines in (("2026-12-02", days[0]), ("2026-12-03", days[1]), ("2026-12-04", day3)):
            with open(os.path.join(res, name + ".jsonl"), "w") as f:
                f.write("\n".join(lines) + "\n")

        r = run(binary, "type1", res, "--feature", "Height 2", "--part-id", "M-1",
                "--reference", "48.3", "--tolerance", "0.6", "--json")
        t1 = json.loads(r.stdout)
        assert "30 measured, 1 not measured" in r.stderr, r.stderr
        s = ref.std(ddof=1)
        close(t1["n"], 30, "type1 n")
        close(t1["mean_mm"], ref.mean(), "type1 mean")
        close(t1["cg"], 0.2 * 0.6 / (6 * s), "Cg")
        close(t1["cgk"], (0.06 - abs(ref.mean() - 48.3)) / (3 * s), "Cgk")
        print(f"type1: Cg {t1['cg']:.3f} Cgk {t1['cgk']:.3f} agree with NumPy")

        # Type 3 on a folder of its own: NumPy's one-way ANOVA by hand.
        res3 = os.path.join(tmp, "results3")
        os.mkdir(res3)
        with open(os.path.join(res3, "2026-12-04.jsonl"), "w") as f:
            f.write("\n".join(day3) + "\n")
        r = run(binary, "type3", res3, "--feature", "Diameter 3", "--tolerance", "0.6", "--json")
        t3 = json.loads(r.stdout)
        x = np.array([parts[k] for k in sorted(parts)])
        ms_within = ((x - x.mean(axis=1, keepdims=True)) ** 2).sum() / (5 * 2)
        ms_parts = 3 * ((x.mean(axis=1) - x.mean()) ** 2).sum() / 4
        pv = math.sqrt(max(0.0, (ms_parts - ms_within) / 3))
        close(t3["ms_within"], ms_within, "MS within")
        close(t3["ms_parts"], ms_parts, "MS parts")
        close(t3["grr_percent_tolerance"], 100 * 6 * math.sqrt(ms_within) / 0.6, "%GRR of T")
        close(t3["ndc"], math.floor(1.41 * pv / math.sqrt(ms_within)), "ndc")
        print(f"type3: %GRR {t3['grr_percent_tolerance']:.2f} % of T, ndc {t3['ndc']} agree")

        # Bad input: each a clear error naming what and where.
        def refused(args, words):
            r = run(binary, *args, ok=False)
            for w in words:
                if w not in r.stderr:
                    sys.exit(f"FAIL: study {' '.join(args)}: '{w}' not in: {r.stderr}")
        refused(["type3", res, "--feature", "Diameter 3", "--tolerance", "0.6"],
                ["part 2 has 3 measurements, part 1 has 30"])
        refused(["type1", res, "--feature", "Height 9", "--reference", "1", "--tolerance", "0.6"],
                ["no part has a feature 'Height 9'"])
        refused(["type1", res, "--feature", "Height 2", "--reference", "48.3", "--tolerance", "0"],
                ["tolerance must be positive"])
        refused(["type1", os.path.join(tmp, "none"), "--feature", "Height 2", "--reference", "1",
                 "--tolerance", "0.6"], ["cannot read the results folder"])
        with open(os.path.join(res3, "2026-12-05.jsonl"), "w") as f:
            f.write(day3[0] + "\n{\"sequence\": 1, \"part\n")
        refused(["type3", res3, "--feature", "Diameter 3", "--tolerance", "0.6"],
                ["2026-12-05.jsonl:2: not a result line"])
        print("bad input refused with the file, line or value named")
    sys.exit(0)


if __name__ == "__main__":
    main()
