#!/usr/bin/python3
"""Can the pose be found before the last face's accelerometer margin has passed?
(issue 17 "Latency at the floor", docs/benchmarks.md "Daemon latency").

At the moment the last profile arrives, the daemon has every face's accelerometer record but the
last face's ends at that profile: its last 0.5 s of profiles are poorly compensated. This finds
the pose on exactly that (a copy of the recording with the last face's accelerometer record cut
at its last profile), then measures the whole recording with that pose, and compares every
feature with the usual pipeline (pose found on the full records), both against the simulator's
truth.

    /usr/bin/python3 early_pose.py BUILD_DIR SEED [SEED ...]
"""
import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import yaml


def main():
    bin_path = os.path.join(sys.argv[1], "src/app/hotgauge")
    seeds = [int(s) for s in sys.argv[2:]] or [41, 42, 43]

    def measure(*args):
        r = subprocess.run([bin_path, "measure", *args, "--json"], capture_output=True, text=True)
        if r.returncode not in (0, 3):  # 3: a feature NOK, still a result
            raise RuntimeError(r.stderr[-2000:])
        return json.loads(r.stdout)

    def errors(out, truth):
        t = {f["name"]: f["cold_mm"] for f in truth["features"]}
        return {f["name"]: None if f["cold_mm"] is None else f["cold_mm"] - t[f["name"]]
                for f in out["features"]}

    work = tempfile.mkdtemp(prefix="hotgauge-early-pose-")
    try:
        for seed in seeds:
            rec = os.path.join(work, f"s{seed}")
            subprocess.run([bin_path, "simulate", "--seed", str(seed), "--temperature", "1000",
                            "--out", rec], check=True, capture_output=True)
            truth = yaml.safe_load(open(rec + ".truth/truth.yaml"))
            cut = rec + "-cut"
            shutil.copytree(rec, cut)
            last = yaml.safe_load(open(os.path.join(cut, "part.yaml")))["faces"][-1]
            face = os.path.join(cut, last)
            pt = np.load(os.path.join(face, "profile_times.npy"))
            at = np.load(os.path.join(face, "accel_times.npy"))
            keep = at <= pt[-1]
            np.save(os.path.join(face, "accel_times.npy"), at[keep])
            np.save(os.path.join(face, "accel.npy"), np.load(os.path.join(face, "accel.npy"))[keep])
            pose = os.path.join(work, f"s{seed}-early-pose.yaml")
            with open(pose, "w") as f:
                f.write("world_from_part: " +
                        json.dumps(measure(cut)["match"]["world_from_part"]) + "\n")
            full = errors(measure(rec), truth)
            early = errors(measure(rec, "--part-pose", pose), truth)
            measured = [k for k in full if full[k] is not None and early[k] is not None]
            print(f"seed {seed} (last face {last}): worst |error| with the usual pose "
                  f"{max(abs(full[k]) for k in measured) * 1000:.1f} µm, with the early pose "
                  f"{max(abs(early[k]) for k in measured) * 1000:.1f} µm; largest change of a "
                  f"feature {max(abs(early[k] - full[k]) for k in measured) * 1000:.1f} µm "
                  f"({len(measured)} features)", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
