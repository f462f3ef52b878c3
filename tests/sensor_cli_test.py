#!/usr/bin/python3
"""hotgauge calibrate sensor VIEWS.yaml (docs/calibration.md "Sensor"): the virtual head's
checkerboard views written by `simulate --sensor-views`, calibrated into calibration.yaml's
sensor (model pinhole, method sensor) close to the head's true camera and laser plane, which
the simulator writes beside them; a views file naming a missing image, a view without the board
and an unknown key are refused by name, and the calibration in force is not written over."""
import math
import os
import shutil
import subprocess
import sys
import tempfile

import yaml

BIN = sys.argv[1]


def run(*args):
    return subprocess.run([BIN, *args], capture_output=True, text=True, timeout=300)


with tempfile.TemporaryDirectory() as tmp:
    views = os.path.join(tmp, "views")
    r = run("simulate", "--sensor-views", "12", "--seed", "4", "--out", views)
    assert r.returncode == 0, r.stderr
    nominal = os.path.join(tmp, "nominal.yaml")
    assert run("calibrate", "nominal", "--out", nominal).returncode == 0
    out = os.path.join(tmp, "cal.yaml")
    r = run("calibrate", "sensor", os.path.join(views, "views.yaml"), "--calibration", nominal,
            "--out", out)
    assert r.returncode == 0, r.stderr
    print(r.stdout, end="")
    cal = yaml.safe_load(open(out))
    truth = yaml.safe_load(open(os.path.join(views, "sensor-truth.yaml")))["sensor"]
    s = cal["sensor"]
    assert cal["method"] == "sensor" and s["model"] == "pinhole", cal
    assert cal["residuals"]["sensor.reprojection_rms_px"] < 0.1, cal["residuals"]
    assert cal["residuals"]["sensor.views"] == 12
    assert cal["faces"] == yaml.safe_load(open(nominal))["faces"]  # kept, to be aligned again
    for k in ("fx", "fy"):
        assert abs(s[k] / truth[k] - 1) < 5e-4, (k, s[k], truth[k])
    for k in ("cx", "cy"):
        assert abs(s[k] - truth[k]) < 3.0, (k, s[k], truth[k])
    cos = sum(a * b for a, b in zip(s["plane_normal"], truth["plane_normal"]))
    assert math.degrees(math.acos(min(1.0, cos))) < 0.05, (s["plane_normal"], truth)
    assert abs(s["plane_offset_mm"] - truth["plane_offset_mm"]) < 0.5

    def refused(text, expect):
        bad = os.path.join(views, "bad.yaml")
        with open(bad, "w") as f:
            f.write(text)
        shutil.copy(nominal, out)
        before = open(out).read()
        r = run("calibrate", "sensor", bad, "--calibration", nominal, "--out", out)
        assert r.returncode == 1 and expect in r.stderr, (expect, r.stderr)
        assert open(out).read() == before

    good = open(os.path.join(views, "views.yaml")).read()
    refused(good.replace("view02-laser.png", "nowhere.png"),
            "bad.yaml:5: views[1].laser: cannot read 'nowhere.png'")
    refused(good.replace("view03-board.png", "view01-laser.png"), "target not found in image 3")
    refused(good.replace("views:", "lens: c-mount\nviews:"), "unknown key 'lens'")
    refused(good.replace("hotgauge-sensor-views-1", "v2"), "expected hotgauge-sensor-views-1")
print("sensor calibration CLI test passed")
