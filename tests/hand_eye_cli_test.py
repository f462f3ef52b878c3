#!/usr/bin/python3
"""hotgauge calibrate hand-eye POSES on poses written here with NumPy from a known camera-on-
flange X (docs/calibration.md "Hand-eye"): every method prints X back (noise-free poses); two
poses, and a poses file with an unknown key, are refused by name.

    hand_eye_cli_test.py HOTGAUGE_BINARY
"""
import os
import re
import subprocess
import sys
import tempfile

import numpy as np

BIN = sys.argv[1]
rng = np.random.default_rng(3)


def rot(v):
    """Rotation matrix of the rotation vector v (radians), Rodrigues."""
    a = np.linalg.norm(v)
    if a < 1e-15:
        return np.eye(3)
    k = v / a
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def pose(v, t):
    T = np.eye(4)
    T[:3, :3] = rot(np.asarray(v, float))
    T[:3, 3] = t
    return T


X = pose([0.1, -0.2, 1.4], [35.0, -12.0, 80.0])
T_base_target = pose([np.pi, 0, 0], [800, 100, 0])


def rows(T):
    return "[" + ", ".join("[" + ", ".join(repr(float(x)) for x in r) + "]" for r in T) + "]"


def poses_file(path, n, extra=""):
    with open(path, "w") as f:
        f.write(f"format: hotgauge-hand-eye-poses-1\n{extra}poses:\n")
        for _ in range(n):
            axis = rng.uniform(-1, 1, 3)
            T_bf = pose([0, 0, 0], [800 + 100 * rng.uniform(-1, 1), 100 + 100 * rng.uniform(-1, 1),
                                    700]) @ pose(axis / np.linalg.norm(axis) * np.radians(
                                        45 * rng.uniform(-1, 1)), [0, 0, 0])
            T_ct = np.linalg.inv(T_bf @ X) @ T_base_target
            f.write(f"  - base_from_flange: {rows(T_bf)}\n    camera_from_target: {rows(T_ct)}\n")


with tempfile.TemporaryDirectory() as tmp:
    p = os.path.join(tmp, "poses.yaml")
    poses_file(p, 12)
    r = subprocess.run([BIN, "calibrate", "hand-eye", p], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 0, r.stderr
    num = r"([-\d.]+)"
    found = re.findall(rf"^(\S+)\s+t \[{num}, {num}, {num}\] mm, rotation vector "
                       rf"\[{num}, {num}, {num}\]°", r.stdout, re.M)
    assert [m[0] for m in found] == [
        "Tsai", "Park", "Daniilidis", "Shah", "Li", "Park+refined"], r.stdout
    for name, *v in found:
        v = np.array([float(x) for x in v])
        assert np.linalg.norm(v[:3] - X[:3, 3]) < 1e-3, (name, r.stdout)
        assert np.linalg.norm(v[3:] - np.degrees([0.1, -0.2, 1.4])) < 1e-4, (name, r.stdout)
    print(r.stdout, end="")

    poses_file(p, 2)
    r = subprocess.run([BIN, "calibrate", "hand-eye", p], capture_output=True, text=True)
    assert r.returncode == 1 and "too few poses: 2, need at least 3" in r.stderr, r.stderr

    poses_file(p, 4, extra="robot: abb\n")
    r = subprocess.run([BIN, "calibrate", "hand-eye", p], capture_output=True, text=True)
    assert r.returncode == 1 and "poses.yaml:2" in r.stderr and "robot" in r.stderr, r.stderr
print("hand-eye CLI test passed")
