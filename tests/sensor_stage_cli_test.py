#!/usr/bin/python3
"""hotgauge calibrate sensor --stage STAGE.yaml (docs/calibration.md "Sensor on a stage"): the
virtual head's readings of a plate on a precision stage, written by `simulate --sensor-stage`,
calibrated into calibration.yaml's sensor (model stage, method sensor): the map's residuals at
the micrometre level, the faces kept (to be aligned again); a stage file naming a missing image,
an unknown key, too few tilted readings, and a views file given with --stage are refused by
name, and so is a plate 2° off level; the calibration in force is not written over."""
import os
import shutil
import subprocess
import sys
import tempfile

import yaml

BIN = sys.argv[1]


def run(*args):
    return subprocess.run([BIN, *args], capture_output=True, text=True, timeout=600)


with tempfile.TemporaryDirectory() as tmp:
    stage = os.path.join(tmp, "stage")
    r = run("simulate", "--sensor-stage", "--seed", "3", "--out", stage)
    assert r.returncode == 0, r.stderr
    nominal = os.path.join(tmp, "nominal.yaml")
    assert run("calibrate", "nominal", "--out", nominal).returncode == 0
    out = os.path.join(tmp, "cal.yaml")
    r = run("calibrate", "sensor", "--stage", os.path.join(stage, "stage.yaml"), "--calibration",
            nominal, "--out", out)
    assert r.returncode == 0, r.stderr
    print(r.stdout, end="")
    cal = yaml.safe_load(open(out))
    s = cal["sensor"]
    assert cal["method"] == "sensor" and s["model"] == "stage", (cal["method"], s["model"])
    assert s["width"] == 2048 and s["height"] == 1088 and s["degree"] == 3 and s["x_degree"] == 3
    assert len(s["coefficients"]) == 2048 * 5 and len(s["x_coefficients"]) == 2048 * 4
    res = cal["residuals"]
    assert res["sensor.stage_readings"] == 39, res
    assert res["sensor.stage_z_rms_mm"] < 0.01 and res["sensor.stage_x_rms_mm"] < 0.02, res
    assert cal["faces"] == yaml.safe_load(open(nominal))["faces"]  # kept, to be aligned again

    def refused(text, expect, *extra):
        bad = os.path.join(stage, "bad.yaml")
        with open(bad, "w") as f:
            f.write(text)
        shutil.copy(nominal, out)
        before = open(out).read()
        r = run("calibrate", "sensor", "--stage", bad, *extra, "--calibration", nominal, "--out",
                out)
        assert r.returncode == 1 and expect in r.stderr, (expect, r.stderr)
        assert open(out).read() == before

    good = open(os.path.join(stage, "stage.yaml")).read()
    refused(good.replace("stage02.png", "nowhere.png"),
            "readings[1].laser: cannot read 'nowhere.png' as an 8-bit grey image")
    refused(good.replace("height_mm: 640", "heigth_mm: 640", 1), "unknown key 'heigth_mm'")
    refused(good.replace("tilt_deg: 30.0", "tilt_deg: 2.0", 1),
            "readings[25].tilt_deg: 0 (level) or 5° to 60° either way (tilted)")
    lines = good.splitlines(keepends=True)
    refused("".join(lines[:2 + 25 + 2]), "25 level and 2 tilted readings")
    refused(good, "a views file or --stage, not both", "views.yaml")
    print("refusals: a missing image, an unknown key, a tilt of 2°, too few tilted readings, views "
          "and stage")
