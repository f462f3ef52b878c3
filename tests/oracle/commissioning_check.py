#!/usr/bin/python3
"""A cell commissioned from another simulator's artifact scan, judged by its truth.

CASE holds artifact/ (the artifact's certificate, its scan in artifact/part, truth.json with each
face's true `camera_to_world` and the axis' scale error) and part/ (a part scanned in the same
cell, with truth.json). Runs `hotgauge calibrate faces`, then checks every face against the truth
(issue 37): position within --position-mm and rotation within --rotation-deg, both within 3σ of
the calibration's own σ per axis, travel scale within --travel-ppm; then measures the part with
that calibration (oracle/truth_compare.py --limit --calibration). With --report, the
commissioning report of the run, and of a refused run (the certificate's balls 60 mm higher),
loaded in headless Chromium: a residual map per face, loaded and not blank; the σ table; the
verdict and the reason. Exit 1 on any miss."""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np
import yaml


def rotation_vector(R):
    """The rotation vector (rad) of a 3×3 rotation matrix."""
    c = max(-1.0, min(1.0, (np.trace(R) - 1.0) / 2.0))
    angle = math.acos(c)
    if angle < 1e-12:
        return np.zeros(3)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return w / (2.0 * math.sin(angle)) * angle


def check_faces(cal, truth, a):
    res = cal["residuals"]
    scale_true = 1.0 + truth["miscal"]["axis_scale_error"]
    bad = 0
    for f in cal["faces"]:
        name = f["name"]
        T = np.array(f["camera_to_world"])
        Tt = np.array(truth["face_data"][name]["camera_to_world"])
        dp = T[:3, 3] - Tt[:3, 3]
        # error rotation in the camera's axes: R_true = R · exp([w]×)
        w = rotation_vector(T[:3, :3].T @ Tt[:3, :3]) * 180.0 / math.pi
        s_p = np.array([res[f"{name}.sigma_position_{k}_mm"] for k in "xyz"])
        s_r = np.array([res[f"{name}.sigma_rotation_{k}_deg"] for k in "xyz"])
        dscale_ppm = (f["travel_scale"] / scale_true - 1.0) * 1e6
        s_t = res[f"{name}.sigma_travel_ppm"]
        misses = []
        if np.linalg.norm(dp) > a.position_mm:
            misses.append(f"position {np.linalg.norm(dp):.4f} mm > {a.position_mm}")
        if np.linalg.norm(w) > a.rotation_deg:
            misses.append(f"rotation {np.linalg.norm(w):.5f}° > {a.rotation_deg}")
        if abs(dscale_ppm) > a.travel_ppm:
            misses.append(f"travel {dscale_ppm:+.1f} ppm")
        if np.any(np.abs(dp) > 3 * s_p) or np.any(np.abs(w) > 3 * s_r) or abs(dscale_ppm) > 3 * s_t:
            misses.append("outside 3σ")
        print(f"  {name:7s} position {dp[0]:+.4f} {dp[1]:+.4f} {dp[2]:+.4f} mm "
              f"(σ {s_p[0]:.4f} {s_p[1]:.4f} {s_p[2]:.4f}); rotation {w[0]:+.5f} {w[1]:+.5f} "
              f"{w[2]:+.5f}° (σ {s_r[0]:.5f} {s_r[1]:.5f} {s_r[2]:.5f}); travel "
              f"{dscale_ppm:+.1f} ppm (σ {s_t:.1f}){'  <-- ' + ', '.join(misses) if misses else ''}")
        bad += bool(misses)
    return bad


def check_reports(a, certificate, scan, tmp, faces):
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
    from report_check import check_page
    html = f"{tmp}/report/commissioning.html"
    seen, png = check_page(html)
    text = open(html).read()
    misses = []
    if len(seen["img"]) != faces:
        misses.append(f"{len(seen['img'])} residual maps for {faces} faces")
    if "v-PASSED" not in text or text.count("<table class='sigma'>") != 1:
        misses.append("no PASSED verdict or σ table")
    # A refused run writes its report too, with the reason.
    cert = yaml.safe_load(open(certificate))
    for sphere in cert["spheres"]:
        sphere["center_mm"][2] += 60.0
    moved = f"{tmp}/moved.yaml"
    yaml.safe_dump(cert, open(moved, "w"))
    run = subprocess.run([a.hotgauge, "calibrate", "faces", "--artifact", moved, scan, "--out",
                          f"{tmp}/refused.yaml", "--report", f"{tmp}/refused"],
                         capture_output=True, text=True)
    refused = open(f"{tmp}/refused/commissioning.html").read()
    if run.returncode == 0 or "v-REFUSED" not in refused or "put the balls 60." not in refused \
            or os.path.exists(f"{tmp}/refused.yaml"):
        misses.append("the refused run: no REFUSED report with its reason, or a calibration")
    check_page(f"{tmp}/refused/commissioning.html")
    print(f"commissioning report: {len(seen['img'])} residual maps rendered in Chromium "
          f"({png}); refused run reported{'  <-- ' + ', '.join(misses) if misses else ''}")
    return bool(misses)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("hotgauge")
    ap.add_argument("case", help="folder with artifact/ and part/")
    ap.add_argument("--position-mm", type=float, default=0.01)
    ap.add_argument("--rotation-deg", type=float, default=0.002)
    ap.add_argument("--travel-ppm", type=float, default=50.0)
    ap.add_argument("--part-limit", type=float, default=0.02)
    ap.add_argument("--report", action="store_true", help="check the HTML reports in Chromium")
    a = ap.parse_args()
    artifact = f"{a.case}/artifact"
    # The certificate is the artifact file whose name the scan's recipe gives.
    recipe = yaml.safe_load(open(f"{artifact}/part/part.yaml"))["recipe"]
    certificate = [n for n in sorted(os.listdir(artifact)) if n.endswith(".yaml")
                   and (yaml.safe_load(open(f"{artifact}/{n}")) or {}).get("artifact") == recipe][0]
    nominal = os.path.join(os.path.dirname(__file__), "../../config/calibration.yaml")
    with tempfile.TemporaryDirectory() as tmp:
        out = f"{tmp}/calibration.yaml"
        run = subprocess.run([a.hotgauge, "calibrate", "faces", "--artifact",
                              f"{artifact}/{certificate}", f"{artifact}/part", "--calibration",
                              nominal, "--out", out, "--report", f"{tmp}/report"], capture_output=True, text=True)
        print(run.stdout + run.stderr, end="")
        if run.returncode != 0:
            sys.exit(1)
        cal = yaml.safe_load(open(out))
        bad = check_faces(cal, json.load(open(f"{artifact}/truth.json")), a)
        part = subprocess.run([sys.executable, os.path.join(os.path.dirname(__file__),
                                                            "truth_compare.py"),
                               a.hotgauge, f"{a.case}/part", "--limit", str(a.part_limit),
                               "--calibration", out])
        bad += part.returncode != 0
        if a.report:
            bad += check_reports(a, f"{artifact}/{certificate}", f"{artifact}/part", tmp,
                                 len(cal["faces"]))
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
