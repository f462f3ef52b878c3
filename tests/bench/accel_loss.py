#!/usr/bin/python3
"""Accuracy under accelerometer datagram loss (issue 18, docs/compensation.md "Lost datagrams").

Simulates hub-a recordings (full-resolution cell, press vibration, 1050 °C), drops whole 10 ms
accelerometer datagrams (20 samples) at random on every face, as a UDP stream on a busy network
loses them, measures each copy with `hotgauge measure --json` (part found by matching) and
compares every feature's hot value with the simulator's truth. Per loss rate: features OK,
degraded (by reason) and not measured, the worst |error| of the OK ones, and any NOK (every
simulated part is good, so a NOK is false).

    /usr/bin/python3 accel_loss.py BUILD_DIR [--recordings 16] [--first-seed 100] [--loss-seeds 4]
        [--losses 0 0.02 0.05 0.1 0.3] [--bound 0.02] [--dump FILE.jsonl]

Exit 1 when an OK feature is off by more than --bound or a feature is NOK.
"""
import argparse
import collections
import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import yaml

DATAGRAM_NS = 10_000_000


def drop_datagrams(src, dst, fraction, rng):
    shutil.copytree(src, dst)
    for face in yaml.safe_load(open(os.path.join(dst, "part.yaml")))["faces"]:
        d = os.path.join(dst, face)
        t = np.load(os.path.join(d, "accel_times.npy"))
        a = np.load(os.path.join(d, "accel.npy"))
        datagram = (t - t[0]) // DATAGRAM_NS
        lost = rng.random(int(datagram[-1]) + 1) < fraction
        keep = ~lost[datagram]
        np.save(os.path.join(d, "accel_times.npy"), t[keep])
        np.save(os.path.join(d, "accel.npy"), a[keep])


def measure(bin_path, rec):
    r = subprocess.run([bin_path, "measure", rec, "--json"], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"{rec}: exit {r.returncode}: {r.stderr[-2000:]}")
    return json.loads(r.stdout)


def reason_kind(reason):
    for key in ("silhouette edge", "untrusted profiles"):
        if reason and key in reason:
            return key
    return "other"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("build")
    ap.add_argument("--recordings", type=int, default=16)
    ap.add_argument("--first-seed", type=int, default=100)
    ap.add_argument("--loss-seeds", type=int, default=4)
    ap.add_argument("--losses", type=float, nargs="+", default=[0, 0.02, 0.05, 0.1, 0.3])
    ap.add_argument("--bound", type=float, default=0.02)
    ap.add_argument("--temperature", type=float, default=1050)
    ap.add_argument("--dump", help="every measured feature, one JSON line each")
    args = ap.parse_args()
    bin_path = os.path.join(args.build, "src/app/hotgauge")
    work = tempfile.mkdtemp(prefix="hotgauge-accel-loss-")
    failed = False
    dump = open(args.dump, "w") if args.dump else None
    try:
        recs = []
        for i in range(args.recordings):
            rec = os.path.join(work, f"r{i}")
            subprocess.run([bin_path, "simulate", "--seed", str(args.first_seed + i), "--temperature",
                            str(args.temperature), "--out", rec], check=True, capture_output=True)
            truth = yaml.safe_load(open(rec + ".truth/truth.yaml"))
            recs.append((rec, {f["name"]: f["hot_mm"] for f in truth["features"]}))
        print(f"{args.recordings} recordings at {args.temperature:.0f} °C, 10 ms datagrams lost "
              f"at random on every face, {args.loss_seeds} loss patterns each")
        for loss in args.losses:
            counts = collections.Counter()
            worst_ok, worst_ok_at = 0.0, ""
            u_rows = []  # (u, |error|, name) of every measured feature
            for i, (rec, truth) in enumerate(recs):
                for k in range(args.loss_seeds if loss > 0 else 1):
                    lossy = os.path.join(work, "lossy")
                    shutil.rmtree(lossy, ignore_errors=True)
                    drop_datagrams(rec, lossy, loss, np.random.default_rng(1000 * i + k))
                    for f in measure(bin_path, lossy)["features"]:
                        v = f["verdict"]
                        if dump and f["hot_mm"] is not None:
                            dump.write(json.dumps({
                                "loss": loss, "recording": i, "pattern": k, "name": f["name"],
                                "verdict": v, "reason": f["reason"], "u_mm": f["u_mm"],
                                "error_mm": f["hot_mm"] - truth[f["name"]]}) + "\n")
                        counts[v if v != "DEGRADED" else "DEGRADED " + reason_kind(f["reason"])] += 1
                        if v == "NOK":
                            print(f"  FALSE NOK r{i} pattern {k}: {f['name']}: {f['reason']}")
                            failed = True
                        if f["hot_mm"] is not None:
                            u_rows.append((f["u_mm"], abs(f["hot_mm"] - truth[f["name"]]), f["name"]))
                        if v == "OK":
                            e = abs(f["hot_mm"] - truth[f["name"]])
                            if e > worst_ok:
                                worst_ok, worst_ok_at = e, f"{f['name']}, r{i} pattern {k}"
            degraded = {k[9:]: n for k, n in counts.items() if k.startswith("DEGRADED ")}
            print(f"{100 * loss:4.0f} %: OK {counts['OK']} (worst |error| {worst_ok:.4f} mm: "
                  f"{worst_ok_at or '-'}), degraded {sum(degraded.values())} {dict(degraded)}, "
                  f"not measured {counts['NOT_MEASURED']}, NOK {counts['NOK']}", flush=True)
            if u_rows:
                u, e, name = max(u_rows)
                covered = sum(err <= 2 * uu for uu, err, _ in u_rows)
                print(f"       u: largest {u:.4f} mm ({name}, |error| {e:.4f} mm), over 0.01 mm "
                      f"{sum(uu > 0.01 for uu, _, _ in u_rows)}, over 0.02 mm "
                      f"{sum(uu > 0.02 for uu, _, _ in u_rows)}; |error| <= 2u: {covered} of "
                      f"{len(u_rows)}", flush=True)
            failed = failed or worst_ok > args.bound
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
