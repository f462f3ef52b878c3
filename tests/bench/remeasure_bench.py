#!/usr/bin/python3
"""Re-measuring the archive, the new way against the old (docs/results.md "Re-measuring the
archive", docs/benchmarks.md): an archive of PARTS 4-face hub-a parts, measured again

  - the old way: one `hotgauge measure REC --json` per archived recording, one after the other
    (each on every core), and two such processes at once (each on one core);
  - the new way: one `hotgauge remeasure RESULTS --out DIR`, parts in parallel in one process.

Both in the same run, on the same machine; the ratio is quoted. The archive is built from DISTINCT
simulated parts (hotgauge simulate: seeds 1..DISTINCT, 1050 °C, the shipped cell with its press
vibration), each archived PARTS/DISTINCT times (a symbolic link), with a results line per part in
the daemon's format whose `part` is that recording's `hotgauge measure --json`. The old way is
timed on OLD_PARTS of them (it is slow); parts/s is what is compared.

With --baseline-bin-dir (a build of an earlier commit: `make bench` builds the previous one),
also stage by stage: `hotgauge measure --threads 1` of the distinct parts with both builds,
alternating, medians per stage.

    /usr/bin/python3 tests/bench/remeasure_bench.py build [--parts 200] [--distinct 10]
        [--old-parts 20] [--forged] [--work DIR] [--baseline-bin-dir DIR]
"""
import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor


def hotgauge(bin_dir, *args):
    return subprocess.run([os.path.join(bin_dir, "src", "app", "hotgauge"), *args],
                          check=True, capture_output=True, text=True).stdout


def build_archive(bin_dir, work, parts, distinct, forged):
    """recordings/sim-K (simulated), archive/DAY/SEQ_ID -> recording, results/DAY.jsonl."""
    day = "2026-12-07"
    base_ns = int(datetime.datetime(2026, 12, 7, 6, 0, tzinfo=datetime.timezone.utc)
                  .timestamp() * 1e9)
    measured = []
    for k in range(1, distinct + 1):
        rec = os.path.join(work, "recordings", f"sim-{k}")
        args = ["simulate", "-o", rec, "--seed", str(k), "--temperature", "1050",
                "--part-id", f"SIM-{k:06d}"] + (["--forged"] if forged else [])
        hotgauge(bin_dir, *args)
        measured.append((rec, json.loads(hotgauge(bin_dir, "measure", rec, "--json"))))
    os.makedirs(os.path.join(work, "results"))
    with open(os.path.join(work, "results", f"{day}.jsonl"), "w") as out:
        for seq in range(1, parts + 1):
            rec, part = measured[(seq - 1) % distinct]
            folder = os.path.join(work, "archive", day, f"{seq:012d}_{part['part_id']}-{seq}")
            os.makedirs(os.path.dirname(folder), exist_ok=True)
            os.symlink(rec, folder)
            t_ns = base_ns + seq * 10_000_000_000
            stamp = datetime.datetime.fromtimestamp(t_ns / 1e9, datetime.timezone.utc)
            line = {"time": stamp.isoformat(timespec="milliseconds").replace("+00:00", "Z"),
                    "time_ns": t_ns, "sequence": seq, "software_version": "bench",
                    "config_hash": "bench", "result_hash": "", "archived_as": folder, "die": 0,
                    "drift": {}, "remeasure_of": None, "part": part, "plc": {}}
            out.write(json.dumps(line) + "\n")
    return [rec for rec, _ in measured]


def old_way(bin_dir, recordings, n, at_once):
    """n recordings measured with one `hotgauge measure` each, `at_once` processes at a time."""
    threads = "0" if at_once == 1 else "1"
    todo = [recordings[i % len(recordings)] for i in range(n)]
    t0 = time.monotonic()
    with ThreadPoolExecutor(at_once) as pool:
        list(pool.map(lambda rec: hotgauge(bin_dir, "measure", rec, "--json", "--threads",
                                           threads), todo))
    return n / (time.monotonic() - t0)


def new_way(bin_dir, work, parts):
    out = os.path.join(work, "remeasured")
    t0 = time.monotonic()
    r = subprocess.run([os.path.join(bin_dir, "src", "app", "hotgauge"), "remeasure",
                        os.path.join(work, "results"), "--out", out],
                       capture_output=True, text=True)
    wall = time.monotonic() - t0
    if r.returncode != 0:
        sys.exit(f"hotgauge remeasure failed ({r.returncode}):\n{r.stderr}")
    c = json.load(open(os.path.join(out, "comparison.json")))
    if c["parts"] != parts:
        sys.exit(f"hotgauge remeasure compared {c['parts']} parts, expected {parts}")
    return parts / wall, c


def stage_medians(results_dir):
    """Median wall time per pipeline stage over the remeasured parts (each on one thread)."""
    stages = {}
    for path in sorted(os.listdir(results_dir)):
        if path.endswith(".jsonl"):
            for line in open(os.path.join(results_dir, path)):
                for k, v in json.loads(line)["part"]["stage_ms"].items():
                    stages.setdefault(k, []).append(v)
    return {k: statistics.median(v) for k, v in stages.items()}


def measure_stages(bin_dir, recordings, rounds):
    """`hotgauge measure --threads 1 --json` stage times and the process's wall time, medians."""
    stages, walls = {}, []
    for _ in range(rounds):
        for rec in recordings:
            t0 = time.monotonic()
            out = json.loads(hotgauge(bin_dir, "measure", rec, "--json", "--threads", "1"))
            walls.append((time.monotonic() - t0) * 1e3)
            for k, v in out["stage_ms"].items():
                stages.setdefault(k, []).append(v)
    return {k: statistics.median(v) for k, v in stages.items()}, statistics.median(walls)


def compare_with_baseline(bin_dir, baseline, recordings):
    """Stage by stage, ours against a baseline build, one part at a time on one thread, the two
    alternating (rounds of every recording) so that both see the same machine."""
    ours, theirs = ({}, []), ({}, [])
    for _ in range(3):
        for acc, b in ((ours, bin_dir), (theirs, baseline)):
            st, wall = measure_stages(b, recordings, 1)
            for k, v in st.items():
                acc[0].setdefault(k, []).append(v)
            acc[1].append(wall)
    print(f"stage by stage, `hotgauge measure --threads 1`, medians over {len(recordings)} "
          f"recordings x 3 alternating rounds: ours / baseline {baseline}")
    for k in ours[0]:
        a, b = statistics.median(ours[0][k]), statistics.median(theirs[0].get(k, [float("nan")]))
        print(f"  {k:<12} {a:7.1f} ms  {b:7.1f} ms  x{b / a:.2f}")
    a, b = statistics.median(ours[1]), statistics.median(theirs[1])
    print(f"  {'process':<12} {a:7.1f} ms  {b:7.1f} ms  x{b / a:.2f} (whole `hotgauge measure`)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("bin_dir")
    ap.add_argument("--parts", type=int, default=200)
    ap.add_argument("--distinct", type=int, default=10)
    ap.add_argument("--old-parts", type=int, default=20)
    ap.add_argument("--forged", action="store_true", help="as-forged parts (simulate --forged)")
    ap.add_argument("--work", help="working folder (kept); default: a temporary one")
    ap.add_argument("--baseline-bin-dir", help="a build of an earlier commit: its stages beside ours")
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="hotgauge-remeasure-bench-")
    if a.work:
        shutil.rmtree(work, ignore_errors=True)
        os.makedirs(work)
    try:
        print(f"building the archive: {a.distinct} simulated {'forged ' if a.forged else ''}"
              f"hub-a parts, {a.parts} archived parts", flush=True)
        recordings = build_archive(a.bin_dir, work, a.parts, a.distinct, a.forged)
        old1 = old_way(a.bin_dir, recordings, a.old_parts, 1)
        print(f"old way, one `hotgauge measure` at a time ({a.old_parts} parts): "
              f"{old1:.2f} parts/s", flush=True)
        old2 = old_way(a.bin_dir, recordings, a.old_parts, 2)
        print(f"old way, two `hotgauge measure --threads 1` at once ({a.old_parts} parts): "
              f"{old2:.2f} parts/s", flush=True)
        new, c = new_way(a.bin_dir, work, a.parts)
        print(f"new way, `hotgauge remeasure` ({a.parts} parts): {new:.2f} parts/s; "
              f"{c['unchanged']} of {c['parts']} parts unchanged")
        print(f"ratio: {new / old1:.1f}x one at a time, {new / max(old1, old2):.1f}x the faster "
              f"old way")
        st = stage_medians(os.path.join(work, "remeasured", "results"))
        print("where a part's time goes in `hotgauge remeasure` (medians, each part on one "
              "thread, two at once): " + ", ".join(f"{k} {v:.1f} ms" for k, v in st.items()))
        if a.baseline_bin_dir:
            compare_with_baseline(a.bin_dir, a.baseline_bin_dir, recordings)
    finally:
        if not a.work:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
