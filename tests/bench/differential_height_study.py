#!/usr/bin/python3
"""Heights that the head's vibration cannot move (issue 38): each bottom profile's own difference.

The head's displacement u(t) is a translation per profile: every point of profile k is moved by
the same u_k. A height measured as the difference of two levels *within one profile* does not
see u_k at all; a height from two level fits over all profiles does, unless u is compensated.
This study takes the bottom face of an independent recording with NO compensation (nominal
points, recording-format-v1) into the part frame with the truth's pose, and measures
  Height 2  flange underside (z 48.3, r 33-67 mm) − spigot end (z 0, r 15-21 mm)
  Height 1  bore step (z 39.3, r 12.2-13.6 mm) − spigot end
two ways: the mean of each profile's difference of level medians (profiles with ≥ 10 points on
both), and the difference of the level medians over all profiles; errors against truth.json's
true_hot. The level windows are the drawing's (hub-a.md): on an as-forged part's drafts and
fillets they are crude, so read the ideal part (independent-paper-7). Research, not a test: it
reads the truth the gauge never sees.
    differential_height_study.py RECORDING_DIR(with truth.json)
"""
import json
import sys
import warnings

import numpy as np
import yaml


def main():
    rec = sys.argv[1]
    t = json.load(open(rec + "/truth.json"))
    s = t["scale"]
    pose = np.array(t["pose_world_from_part"])
    R, T = pose[:3, :3], pose[:3, 3]
    truth = {f["name"]: f["true_hot"] for f in t["features"] if f["face"] == "bottom"}
    d = rec + "/part/bottom"
    prof = np.load(d + "/profiles.npy").astype(float)
    pos = np.load(d + "/profile_positions.npy")
    fy = yaml.safe_load(open(d + "/face.yaml"))
    C = np.array(fy["camera_to_world"])
    sd = np.array(fy["scan_direction"])
    P = C[:3, 0] * prof[..., :1] + C[:3, 2] * prof[..., 1:] + C[:3, 3] + pos[:, None, None] * sd
    p = (P - T) @ R  # part frame (hot mm): Rᵀ (P − T)
    r = np.hypot(p[..., 0], p[..., 1])
    z = p[..., 2]

    def level(z_cold, r0, r1):
        m = (np.abs(z - z_cold * s) < 1.0) & (r > r0) & (r < r1)
        return np.nanmedian(np.where(m, z, np.nan), axis=1), m.sum(axis=1)

    spigot = level(0.0, 15.0, 21.0)
    for name, upper in (("Height 2", level(48.3, 33.0, 67.0)), ("Height 1", level(39.3, 12.2, 13.6))):
        ok = (upper[1] >= 10) & (spigot[1] >= 10)
        per = (upper[0] - spigot[0])[ok]
        whole = np.nanmedian(upper[0]) - np.nanmedian(spigot[0])
        print(f"{rec.rstrip('/').split('/')[-1]} {name}: per profile ({ok.sum()} profiles) "
              f"{1000 * (per.mean() - truth[name]):+.1f} µm (sd {1000 * per.std():.1f} µm a "
              f"profile); level medians, uncompensated {1000 * (whole - truth[name]):+.1f} µm")


if __name__ == "__main__":
    warnings.simplefilter("ignore", RuntimeWarning)  # profiles without a level: NaN medians
    main()
