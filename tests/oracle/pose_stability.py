#!/usr/bin/python3
"""A measurement must not depend on micrometres of pose: `hotgauge measure REC` at the matched
pose, then at N poses a few µm and thousandths of a degree from it (--part-pose); every measured
diameter must stay within --max-um of its value at the matched pose.

    pose_stability.py HOTGAUGE REC [--poses 4] [--max-um 2]

independent-forged-401's recess (Diameter 5) read +0.014, +0.017 or +0.028 mm by which of such
poses it was measured in while the corner fit thinned its samples by their place in a window's
list (docs/measurement.md "Real forgings")."""
import argparse
import json
import math
import os
import random
import subprocess
import sys
import tempfile


def measure(hotgauge, rec, pose=None):
    cmd = [hotgauge, "measure", rec, "--json"] + (["--part-pose", pose] if pose else [])
    return json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)


def moved(T, rng, mm=0.008, rad=5e-5):
    """T (4x4 lists) rotated about a random horizontal axis by N(0, rad) and shifted by N(0, mm)."""
    a = rng.uniform(0, 2 * math.pi)
    k, ang = (math.cos(a), math.sin(a), 0.0), rng.gauss(0, rad)
    c, s = math.cos(ang), math.sin(ang)
    K = [[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]]
    KK = [[sum(K[i][m] * K[m][j] for m in range(3)) for j in range(3)] for i in range(3)]
    R = [[(i == j) + s * K[i][j] + (1 - c) * KK[i][j] for j in range(3)] for i in range(3)]
    out = [[sum(R[i][m] * T[m][j] for m in range(3)) for j in range(3)] + [T[i][3]] for i in range(3)]
    for i in range(3):
        out[i][3] += rng.gauss(0, mm)
    return out + [[0, 0, 0, 1]]


def main():
    p = argparse.ArgumentParser()
    p.add_argument("hotgauge")
    p.add_argument("rec")
    p.add_argument("--poses", type=int, default=4)
    p.add_argument("--max-um", type=float, default=2.0)
    a = p.parse_args()
    base = measure(a.hotgauge, a.rec)
    T0 = base["match"]["world_from_part"]
    ref = {f["name"]: f["hot_mm"] for f in base["features"]
           if f["kind"] == "diameter" and f["hot_mm"] is not None}
    if len(ref) < 3:
        sys.exit(f"{a.rec}: only {len(ref)} diameters measured at the matched pose")
    rng = random.Random(1)
    worst, bad = 0.0, []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(a.poses):
            pose = os.path.join(tmp, f"pose{k}.yaml")
            with open(pose, "w") as f:
                f.write("world_from_part: " + json.dumps(moved(T0, rng)) + "\n")
            for f in measure(a.hotgauge, a.rec, pose)["features"]:
                if f["name"] not in ref:
                    continue
                if f["hot_mm"] is None:
                    bad.append(f"pose {k}: {f['name']} not measured: {f.get('reason')}")
                    continue
                d = 1000 * (f["hot_mm"] - ref[f["name"]])
                worst = max(worst, abs(d))
                if abs(d) > a.max_um:
                    bad.append(f"pose {k}: {f['name']} {d:+.1f} µm")
    print(f"{len(ref)} diameters over {a.poses} poses 8 µm and 0.003° apart: "
          f"at most {worst:.1f} µm from the matched pose's")
    for b in bad:
        print("MOVED:", b)
    sys.exit(1 if bad else 0)


main()
