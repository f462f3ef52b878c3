#!/usr/bin/python3
"""Errors of `hotgauge measure --json` against a recording's truth.json (measured − true, hot).

The truth names a feature by face and name ("side1", "Height 3"); the recipe names it
"Height 3 side1". Prints one line per feature; with --limit, exits 1 when a measured feature is
off by more than the limit or a feature the truth has is not measured (Height 1 may be), with
--nok when the NOK features are not those, with --verdict when the part's verdict is not that."""
import argparse
import json
import subprocess
import sys


def key(face, name):
    return name if face in ("top", "bottom", "all") else f"{name} {face}"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("hotgauge")
    ap.add_argument("recording_dir", help="folder with part/ and truth.json")
    ap.add_argument("--limit", type=float)
    ap.add_argument("--part-pose", action="store_true", help="measure at the true pose")
    ap.add_argument("--max-not-measured", type=int, default=0,
                    help="features besides Height 1 that may be NOT_MEASURED")
    ap.add_argument("--nok", default=None,
                    help="comma-separated features that must read NOK, all others not NOK")
    ap.add_argument("--verdict", help="the part's verdict it must read (OK, NOK, ...)")
    ap.add_argument("--calibration", help="measure with this calibration.yaml")
    ap.add_argument("extra", nargs="*")
    a = ap.parse_args()
    truth = json.load(open(f"{a.recording_dir}/truth.json"))
    cmd = [a.hotgauge, "measure", f"{a.recording_dir}/part", "--json", *a.extra]
    if a.calibration:
        cmd += ["--calibration", a.calibration]
    out = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    got = {f["name"]: f for f in out["features"]}
    bad = not_measured = 0
    print(f"{a.recording_dir}: verdict {out['verdict']}")
    for t in truth["features"]:
        k = key(t["face"], t["name"])
        f = got.get(k)
        if f is None or f["hot_mm"] is None:
            why = "absent" if f is None else f["reason"]
            print(f"  {k:18s} not measured: {why}")
            not_measured += not k.startswith("Height 1")
            continue
        err = f["hot_mm"] - t["true_hot"]
        # A corner whose wall no face sees takes its draft from the drawing: held to its 2u.
        held = "from the drawing" in (f.get("method") or "") and abs(err) <= 2 * f["u_mm"]
        flag = a.limit is not None and abs(err) > a.limit and not held
        bad += flag
        print(f"  {k:18s} {err:+.4f} u {f['u_mm']:.4f} {f['verdict']:12s} {f['method']}"
              f"{'  <-- off' if flag else ''}")
    bad += not_measured > a.max_not_measured
    if a.nok is not None:
        want = set(a.nok.split(",")) if a.nok else set()
        got_nok = {f["name"] for f in out["features"] if f["verdict"] == "NOK"}
        if got_nok != want:
            print(f"  NOK on {sorted(got_nok)}, expected {sorted(want)}")
            bad += 1
    if a.verdict and out["verdict"] != a.verdict:
        print(f"  part verdict {out['verdict']}, expected {a.verdict}")
        bad += 1
    if bad:
        sys.exit(1)


if __name__ == "__main__":
    main()
