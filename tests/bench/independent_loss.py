#!/usr/bin/python3
"""Lost accelerometer datagrams on a recording from the independent simulator (issue 38's first
"Done when"): drop 10 ms datagrams at random (as accel_loss.py does), measure each copy with
`hotgauge measure --json`, and compare every feature with the recording's truth.json.

    /usr/bin/python3 independent_loss.py HOTGAUGE RECORDING_DIR [--losses 0.02 0.1]
        [--patterns 4] [--bound 0.02] [--first-pattern 0]

RECORDING_DIR holds part/ and truth.json (../shared/acceptance/independent-paper-7). Per loss and
pattern: the features not degraded and within ±bound, the degraded ones, the not measured ones,
and any feature off by more than the bound without a flag (OK or NOK). Exit 1 on such a feature.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from accel_loss import drop_datagrams  # noqa: E402

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "oracle"))
from truth_compare import key  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("hotgauge")
    ap.add_argument("recording_dir")
    ap.add_argument("--losses", type=float, nargs="+", default=[0.02, 0.1])
    ap.add_argument("--patterns", type=int, default=4)
    ap.add_argument("--first-pattern", type=int, default=0)
    ap.add_argument("--bound", type=float, default=0.02)
    a = ap.parse_args()
    truth = json.load(open(os.path.join(a.recording_dir, "truth.json")))
    true_hot = {key(t["face"], t["name"]): t["true_hot"] for t in truth["features"]}
    work = tempfile.mkdtemp(prefix="hotgauge-independent-loss-")
    unflagged = 0
    try:
        for loss in a.losses:
            for k in range(a.first_pattern, a.first_pattern + a.patterns):
                lossy = os.path.join(work, "part")
                shutil.rmtree(lossy, ignore_errors=True)
                drop_datagrams(os.path.join(a.recording_dir, "part"), lossy, loss,
                               np.random.default_rng(k))
                r = subprocess.run([a.hotgauge, "measure", lossy, "--json"], capture_output=True,
                                   text=True)
                if r.returncode != 0:
                    raise RuntimeError(f"exit {r.returncode}: {r.stderr[-2000:]}")
                good = degraded = missing = 0
                rows = []
                for f in json.loads(r.stdout)["features"]:
                    if f["name"] not in true_hot:
                        continue
                    if f["hot_mm"] is None:
                        missing += 1
                        rows.append(f"{f['name']} not measured")
                        continue
                    err = f["hot_mm"] - true_hot[f["name"]]
                    if f["verdict"] == "DEGRADED":
                        degraded += 1
                        rows.append(f"{f['name']} {err:+.4f} DEGRADED: {f['reason'][:150]}")
                    elif abs(err) <= a.bound:
                        good += 1
                        rows.append(f"{f['name']} {err:+.4f} u {f['u_mm']:.4f}")
                    else:
                        unflagged += 1
                        rows.append(f"{f['name']} {err:+.4f} u {f['u_mm']:.4f} {f['verdict']} "
                                    f"<-- off, not flagged")
                print(f"{100 * loss:4.0f} % pattern {k}: {good} of {len(true_hot)} not degraded "
                      f"and within ±{a.bound} mm, degraded {degraded}, not measured {missing}",
                      flush=True)
                for row in rows:
                    print("    " + row)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if unflagged else 0


if __name__ == "__main__":
    sys.exit(main())
