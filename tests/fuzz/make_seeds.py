#!/usr/bin/python3
"""Writes the seed corpora of tests/fuzz/corpus/ (tests/fuzz/README.md): small valid and
near-valid inputs for each harness. Run from the repository root; the output is committed, so this
runs only when the seeds should change. The model seeds (fuzz_model) are not made here: they are
model::write_model files of match::model_from_recipe(hub-a, sampling 40 mm, 4 angle and 8 alpha
bins) and of model_from_samples (a 6x6 plate, 8 mm), behind fuzz_model.cpp's flag byte."""
import os
import struct

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus")


def out(harness, name, data):
    d = os.path.join(ROOT, harness)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


def npy(a, fortran=False):
    import io
    b = io.BytesIO()
    np.lib.format.write_array(b, np.asfortranarray(a) if fortran else a, version=(1, 0))
    return b.getvalue()


def npy_seeds():
    s = {
        "profiles_f4.npy": npy(np.arange(3 * 4 * 2, dtype="<f4").reshape(3, 4, 2)),
        "times_i8.npy": npy(np.array([0, 1000, 2500], dtype="<i8")),
        "positions_f8.npy": npy(np.array([0.0, 0.2, np.nan, 1e300], dtype="<f8")),
        "accel_f4.npy": npy(np.array([[0, 0, 9.81], [0.1, -0.2, 9.8]], dtype="<f4")),
        "empty_0x3.npy": npy(np.zeros((0, 3), dtype="<f4")),
        "scalar_u1.npy": npy(np.array(7, dtype="|u1")),
        "fortran_f8.npy": npy(np.arange(6, dtype="<f8").reshape(2, 3), fortran=True),
        "big_endian_i4.npy": npy(np.arange(5, dtype=">i4")),
        "datetime.npy": npy(np.array(["2026-01-01T00:00:00"], dtype="<M8[ns]")),
        "unicode.npy": npy(np.array(["ab", "c"], dtype="<U2")),
        "complex.npy": npy(np.array([1 + 2j], dtype="<c16")),
        "bool.npy": npy(np.array([True, False], dtype="|b1")),
        # Hand-written headers: double quotes, no trailing comma, Python 2 long suffix.
        "handwritten.npy": b"\x93NUMPY\x01\x00" + struct.pack("<H", 54)
        + b'{"shape": (2L,), "fortran_order": False, "descr": "<i2"}'.ljust(53) + b"\n"
        + b"\x01\x00\x02\x00",
    }
    for name, data in s.items():
        out("fuzz_npy", name, data)


# fuzz_recording's container (fuzz_recording.cpp): pieces separated by SEP; piece 0 is part.yaml,
# then six pieces per face folder a and b: face.yaml and the five arrays.
SEP = b"\n%%hotgauge%%\n"

FACE_YAML = (b"camera_to_world: [[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, 500], [0, 0, 0, 1]]\n"
             b"scan_direction: [0, 1, 0]\n"
             b"accel_to_camera: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n")


def face(n=3, w=2, k=4, t0=0, extra=b""):
    prof = np.linspace(-5, 5, n * w * 2, dtype="<f4").reshape(n, w, 2)
    if n:
        prof[0, 0, 1] = np.nan
    times = t0 + np.arange(n, dtype="<i8") * 1_000_000
    pos = np.arange(n, dtype="<f8") * 0.2
    acc = np.tile(np.array([0, 0, 9.81], dtype="<f4"), (k, 1))
    at = t0 - 600_000_000 + np.arange(k, dtype="<i8") * (1_200_000_000 + n * 1_000_000) // max(k - 1, 1)
    return [FACE_YAML + extra, npy(prof), npy(times), npy(pos), npy(acc), npy(at)]


def recording(part_yaml, faces):
    pieces = [part_yaml] + [p for f in faces for p in f]
    for p in pieces:
        assert SEP not in p
    return SEP.join(pieces)


def recording_seeds():
    part = (b'format: hotgauge-recording/1\npart_id: "H-000123"\nrecipe: hub-a\n'
            b'captured_at: "2026-11-21T10:15:00Z"\ntemperature_c: 1050.0\n')
    out("fuzz_recording", "one_face", recording(part + b"faces: [a]\n", [face()]))
    out("fuzz_recording", "two_faces", recording(part + b"faces: [a, b]\n",
                                                 [face(), face(n=2, w=3, k=0, t0=5)]))
    out("fuzz_recording", "calibrated_face",
        recording(part + b"faces: [a]\n",
                  [face(extra=b"travel_scale: 1.001\nclock_offset_ns: -1200\n")]))
    out("fuzz_recording", "empty_face", recording(part + b"faces: [a]\n", [face(n=0, k=0)]))
    out("fuzz_recording", "part_only", part + b"faces: [a]\n")


def mbap(transaction, unit, pdu):
    return struct.pack(">HHHB", transaction, 0, len(pdu) + 1, unit) + pdu


def modbus_seeds():
    # docs/plc-modbus.md: holding 0..5 writable (command, part id, recipe slot, face), 100.. the
    # input registers mirrored; FC03/04 reads, FC06/16 writes.
    read_inputs = mbap(1, 1, struct.pack(">BHH", 4, 0, 12))
    read_holding = mbap(2, 1, struct.pack(">BHH", 3, 0, 6))
    read_mirror = mbap(3, 255, struct.pack(">BHH", 3, 100, 20))
    trigger = mbap(4, 1, struct.pack(">BHHB6H", 16, 0, 6, 12, 1, 0, 42, 1, 1, 0))
    ack = mbap(5, 1, struct.pack(">BHH", 6, 0, 2))
    reset = mbap(6, 1, struct.pack(">BHH", 6, 0, 3))
    results = mbap(7, 1, struct.pack(">BHH", 4, 0, 112))
    out("fuzz_modbus", "read_inputs", read_inputs)
    out("fuzz_modbus", "cycle", read_inputs + trigger + read_inputs + results + ack + read_inputs)
    out("fuzz_modbus", "reset", trigger + reset + read_holding + read_mirror)
    out("fuzz_modbus", "exceptions",
        mbap(8, 7, b"\x03\x00\x00\x00\x01") + mbap(9, 1, b"\x2b\x0e\x01\x00")
        + mbap(10, 1, struct.pack(">BHH", 3, 50, 4)) + mbap(11, 1, b"\x10\x00\x00\x00\x02\x03\x00"))
    out("fuzz_modbus", "split_and_malformed", trigger[:5] + trigger[5:] + b"\x00\x01\x00\x07\x00")


def strip_comments(text):
    """The YAML without comment lines and trailing comments: shorter inputs, more exec/s."""
    lines = []
    for line in text.splitlines():
        if "#" in line and "'" not in line and '"' not in line.split("#")[0]:
            line = line.split("#")[0].rstrip()
        if line.strip():
            lines.append(line)
    return "\n".join(lines) + "\n"


CERTIFICATE = """format: hotgauge-master-1
master: "M-0001"
recipe: hub-a
certified_at: "2026-11-20"
certified_by: "CMM lab, report 4711"
temperature_c: 20.0
tolerance_mm: 0.02
features:
  - {name: "Diameter 1", value_mm: 138.4539, u_mm: 0.001}
  - {name: "Height 1", value_mm: 39.2704, u_mm: 0.001, tolerance_mm: 0.03}
"""


def yaml_seeds():
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

    def read(f):
        with open(os.path.join(repo, f)) as fh:
            return fh.read()

    recipe = read("config/parts/hub-a.yaml")
    config = read("config/hotgauged.yaml")
    seeds = {
        "fuzz_recipe": {
            "hub-a.yaml": recipe,
            "hub-a-short.yaml": strip_comments(recipe),
            # fuzz_recipe.cpp puts an empty hub-a.ply beside the recipe.
            "mesh-file.yaml": strip_comments(recipe).replace(
                "kind: axisymmetric", "kind: axisymmetric\n  mesh_file: hub-a.ply", 1),
        },
        "fuzz_calibration": {
            "calibration.yaml": read("config/calibration.yaml"),
            "calibration-short.yaml": strip_comments(read("config/calibration.yaml")),
        },
        "fuzz_daemon_config": {
            "hotgauged.yaml": config,
            # fuzz_daemon_config.cpp creates the files these reference.
            "hotgauged-short.yaml": strip_comments(config).replace(
                "  1: parts/hub-a.yaml",
                "  1: parts/hub-a.yaml\nmodels: {1: hub-a.hgm}\nmasters: {1: master.yaml}", 1),
        },
        "fuzz_certificate": {"master.yaml": CERTIFICATE,
                             "master-flow.yaml": "{format: hotgauge-master-1, master: M, recipe: r,"
                             " certified_at: x, certified_by: y, temperature_c: 20,"
                             " tolerance_mm: 0.1, features: [{name: a, value_mm: 1, u_mm: 0}]}\n"},
    }
    for harness, files in seeds.items():
        for name, text in files.items():
            out(harness, name, text.encode())


if __name__ == "__main__":
    npy_seeds()
    recording_seeds()
    modbus_seeds()
    yaml_seeds()
