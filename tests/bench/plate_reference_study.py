#!/usr/bin/python3
"""The support plate as a displacement sensor (issue 38, "The scan as a displacement sensor").

Every top and side profile of an independent recording sees the support plate (world z = 0)
beside the part. Where the sensor head is displaced by u, a plate point's nominal world position
(recording-format-v1: camera_to_world · (x, 0, z) + profile_positions[k] · scan_direction) lies
at z = −u_z, so each profile measures u_z directly, without integration. This study compares,
against the independent simulator's own truth (truth.json face_data[face].vibration), per profile:
  plate    −median of the nominal z of the profile's plate points
  accel    the accelerometer integrated twice (FFT, 1.5 Hz order-4 high-pass, as
           compensate::integrate_twice), interpolated to the profile's time
  fused    the plate below FC Hz and the accelerometer above (complementary zero-phase filters)
  and, with LOSS of the 10 ms accelerometer datagrams lost: the accelerometer bridged as the
  gauge bridges it, alone and fused with the plate.
Plate points: nominal |z| < 1.5 mm and farther than 80 mm from the part's axis (hub-a's flange
is 70 mm in radius hot). Usage:
    plate_reference_study.py RECORDING_DIR(with truth.json) [FC_HZ=10] [LOSS=0.02] [PATTERNS=4]
Research, not a test: it reads the truth the gauge never sees.
"""
import json
import os
import sys

import numpy as np
import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from hole_bridge_study import (bridge, holes, integrate, straight_fill,  # noqa: E402
                               truth_u_mm, world_accel)

PLATE_BAND_MM = 1.5
PART_CLEAR_MM = 80.0


def plate_u_z(d, pose):
    """Per profile: (−median nominal z of the plate points, their count)."""
    prof = np.load(d + "/profiles.npy")
    pos = np.load(d + "/profile_positions.npy").astype(float)
    fy = yaml.safe_load(open(d + "/face.yaml"))
    T = np.array(fy["camera_to_world"], float)
    s = np.array(fy["scan_direction"], float)
    x, z = prof[..., 0].astype(float), prof[..., 1].astype(float)
    P = (T[:3, 0][None, None, :] * x[..., None] + T[:3, 2][None, None, :] * z[..., None] +
         T[:3, 3] + pos[:, None, None] * s)
    axis_xy = pose[:2, 3]
    r = np.hypot(P[..., 0] - axis_xy[0], P[..., 1] - axis_xy[1])
    on = np.isfinite(P[..., 2]) & (np.abs(P[..., 2]) < PLATE_BAND_MM) & (r > PART_CLEAR_MM)
    zs = np.where(on, P[..., 2], np.nan)
    count = on.sum(axis=1)
    with np.errstate(all="ignore"):
        u = -np.nanmedian(zs, axis=1)
    return u, count


def lowpass(v, rate, fc, order=4):
    """Zero-phase Butterworth-magnitude low-pass over a record without NaN (mirror-padded)."""
    n = len(v)
    ext = np.concatenate([v[::-1], v, v[::-1]])
    f = np.fft.rfftfreq(len(ext), 1 / rate)
    g = 1 / np.sqrt(1 + (f / fc) ** (2 * order))
    return np.fft.irfft(np.fft.rfft(ext) * g, len(ext))[n:2 * n]


def fill_nan(v):
    ok = np.isfinite(v)
    i = np.arange(len(v))
    return np.interp(i, i[ok], v[ok]) if ok.any() else np.zeros_like(v)


def rms(e):
    return float(np.sqrt(np.mean(e ** 2)))


def main():
    rec = sys.argv[1]
    fc = float(sys.argv[2]) if len(sys.argv) > 2 else 10.0
    loss = float(sys.argv[3]) if len(sys.argv) > 3 else 0.02
    patterns = int(sys.argv[4]) if len(sys.argv) > 4 else 4
    truth = json.load(open(rec + "/truth.json"))
    pose = np.array(truth["pose_world_from_part"], float)
    print(f"{rec}: u_z per profile against the truth, µm RMS / worst over the scan; fused at "
          f"{fc:g} Hz; {loss:.0%} loss, {patterns} patterns")
    print("%-6s %8s %15s %15s %15s %15s %15s" % ("face", "plate/pr", "plate", "accel", "fused",
                                                 "accel, loss", "fused, loss"))
    for face, fd in truth["face_data"].items():
        d = f"{rec}/part/{face}"
        u_plate, count = plate_u_z(d, pose)
        if np.median(count) < 10:
            print("%-6s %8d  (no plate in view)" % (face, np.median(count)))
            continue
        pt = np.load(d + "/profile_times.npy").astype(np.int64)
        t0_ns, per, accel = world_accel(d, fd)
        g = accel[2]
        n = len(g)
        tg = np.arange(n) * per
        tp = (pt - t0_ns) / 1e9
        vib = fd["vibration"]
        u_true = truth_u_mm(vib, (pt - vib["time_reference_ns"]) / 1e9)[2]
        prate = 1e9 / np.median(np.diff(pt))
        plate = fill_nan(u_plate)
        low = lowpass(plate, prate, fc)

        def fuse(u_acc):
            return low + (u_acc - lowpass(u_acc, prate, fc))

        u_acc = np.interp(tp, tg, integrate(g, 1 / per) * 1000)  # m -> mm
        # Every profile: the record runs a second beyond the scan at each end.
        row = [np.abs(x - u_true) * 1000 for x in (plate, u_acc, fuse(u_acc))]
        lossy = [[], []]
        rng = np.random.default_rng(sum(map(ord, face)))
        for _ in range(patterns):
            gaps = holes(n, loss, rng)
            ub = np.interp(tp, tg, bridge(straight_fill(g, gaps), 1 / per, gaps) * 1000)
            lossy[0].append(np.abs(ub - u_true) * 1000)
            lossy[1].append(np.abs(fuse(ub) - u_true) * 1000)
        row += [np.concatenate(v) for v in lossy]
        print("%-6s %8d " % (face, np.median(count)) +
              " ".join("%6.1f / %6.1f" % (rms(e), e.max()) for e in row))


if __name__ == "__main__":
    main()
