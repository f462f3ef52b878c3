#!/usr/bin/python3
"""hotgauge verify on a simulated cold master (docs/verification.md): its certificate made from
the simulator's truth passes; a certified value 0.05 mm off fails naming the feature (exit 3);
a certificate of a feature the recipe lacks, or with an unknown key, is an error (exit 1).

    verify_test.py HOTGAUGE_BINARY
"""
import json
import os
import subprocess
import sys
import tempfile

import yaml

BIN = sys.argv[1]


def hotgauge(*args):
    return subprocess.run([BIN, *args], capture_output=True, text=True, timeout=300)


def certificate(path, features, extra=""):
    with open(path, "w") as f:
        f.write("format: hotgauge-master-1\nmaster: \"M-0001\"\nrecipe: hub-a\n"
                "certified_at: \"2026-11-20\"\ncertified_by: \"CMM lab, report 4711\"\n"
                f"temperature_c: 20.0\ntolerance_mm: 0.02\n{extra}features:\n")
        for name, value in features:
            f.write(f"  - {{name: \"{name}\", value_mm: {value!r}, u_mm: 0.001}}\n")


with tempfile.TemporaryDirectory() as tmp:
    rec = os.path.join(tmp, "master")
    r = hotgauge("simulate", "--seed", "11", "--temperature", "20", "--out", rec)
    assert r.returncode == 0, r.stderr
    # A cold master gives the pyrometer nothing to read: the certificate's temperature is used.
    part = os.path.join(rec, "part.yaml")
    lines = [l for l in open(part) if not l.startswith("temperature_c")]
    open(part, "w").writelines(lines)
    truth = yaml.safe_load(open(rec + ".truth/truth.yaml"))
    certified = [(f["name"], round(f["cold_mm"], 4)) for f in truth["features"]]
    cert = os.path.join(tmp, "cert.yaml")

    certificate(cert, certified)
    r = hotgauge("verify", "--master", cert, rec, "--json")
    assert r.returncode == 0, (r.returncode, r.stdout, r.stderr[-2000:])
    v = json.loads(r.stdout)
    assert v["passed"] and len(v["features"]) == 14, v
    worst = max(abs(f["deviation_mm"]) for f in v["features"])
    assert "taken as 20 °C" in r.stderr, r.stderr[-500:]
    print(f"master passed: 14 features, worst deviation {worst:.4f} mm")

    off = [(n, v + 0.05 if n == "Diameter 3" else v) for n, v in certified]
    certificate(cert, off)
    r = hotgauge("verify", "--master", cert, rec)
    assert r.returncode == 3, (r.returncode, r.stdout, r.stderr[-2000:])
    assert "FAILED" in r.stdout and "FAIL deviation -0.0" in r.stdout, r.stdout
    fail_lines = [l for l in r.stdout.splitlines() if "FAIL " in l]
    assert len(fail_lines) == 1 and fail_lines[0].startswith("Diameter 3"), r.stdout

    certificate(cert, certified + [("Diameter 9", 10.0)])
    r = hotgauge("verify", "--master", cert, rec)
    assert r.returncode == 1 and "feature 'Diameter 9' is not in recipe hub-a" in r.stderr, r.stderr

    certificate(cert, certified, extra="colour: blue\n")
    r = hotgauge("verify", "--master", cert, rec)
    assert r.returncode == 1 and "cert.yaml:8" in r.stderr and "colour" in r.stderr, r.stderr
print("verify test passed")
