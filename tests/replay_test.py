#!/usr/bin/python3
"""A part archived by hotgauged replays through the virtual cell and a second hotgauged with the
same results (docs/virtual-cell.md "Replay", issue 20 item 3).

1. The virtual line (virtual_line.py) measures one part and archives it (archive_every_nth_ok: 1).
   Its calibration has a clock offset and travel scales off 1, the virtual cell's true geometry
   alike, so that the replay must get the daemon's use of times and speeds right.
2. `hotgauge simulate --serve --replay REC` serves that recording; a second hotgauged with the
   same config measures it, triggered over Modbus by pymodbus.
   Its first scan loses its start on purpose, so the daemon scans that face again at once.
3. Every feature of the replay's result (its results JSON line) and of `hotgauge measure` of the
   replay's own archive equals `hotgauge measure` of the original recording to 1 µm, with the
   same verdicts; the replayed recording's profiles are the original's bit for bit. Both daemons
   run with pipeline settings off their defaults (a 2.5 Hz high-pass corner, 2 threads), and
   `hotgauge measure` is given the same as options (issue 22): with the default corner the
   features differ, so the comparison shows the settings are applied alike.

    /usr/bin/python3 replay_test.py BUILD_DIR                  (ctest replay_through_daemon)
    /usr/bin/python3 replay_test.py BUILD_DIR --off-grid 3     (the peak format's quantisation)
"""
import argparse
import glob
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np
import yaml

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from virtual_line import (DONE, FAULT, NOMINAL, Conveyor, Line, Plc, decode,  # noqa: E402
                          hotgauge, print_logs, run_part)

ADDRESS, REPLAY_ADDRESS = "127.0.0.11", "127.0.0.12"  # this test's own cameras
PART_ID = 250001
# The daemon's pipeline settings (docs/operations.md "Configuration") and the same as options of
# `hotgauge measure`: a non-default high-pass corner and threads, which must give the same features.
PIPELINE = "pipeline: {highpass_hz: 2.5, threads: 2}\n"
MEASURE_OPTIONS = ("--highpass-hz", "2.5", "--threads", "1")
TOLERANCE_UM = 1.0


def shifted_calibration(path):
    """The nominal calibration with a camera clock 1.234567 ms behind and travel scales off 1."""
    cal = yaml.safe_load(open(NOMINAL))
    cal["clock_offset_ns"] = 1234567
    for i, face in enumerate(cal["faces"]):
        face["travel_scale"] = 1.0 + 0.0003 * (i + 1)
    with open(path, "w") as f:
        yaml.safe_dump(cal, f)
    return path


class ReplayLine(Line):
    """The line with the replaying virtual cell instead of the simulating one."""

    def __init__(self, *args, recording, lose_first_start=False, **kwargs):
        super().__init__(*args, **kwargs)
        self.recording = recording
        # The first scan loses its first 5 frames (50 ms): the daemon scans the face again at
        # once, while the first scan's accelerometer record is still arriving.
        self.cell_extra = ["--lose-scan-start", "5", "--lose-scan-start-count", "1"] \
            if lose_first_start else []

    def cell_argv(self, accel_to):
        return [os.path.join(self.bin_dir, "src/app/hotgauge"), "simulate", "--serve",
                "--address", self.address, "--mode", "peaks", "--speed-mm-s", "200",
                "--line-rate", "1000", "--accel-to", accel_to, "--axis-port", str(self.axis_port),
                "--pyrometer-device", self.pyrometer_sim_dev,
                "--replay", self.recording, "--calibration", self.calibration, "--scan-s", "1.3"] + \
            self.cell_extra


def one_part(line, conveyor=True):
    """One part through `line`; returns (its results JSON line, its archived recording)."""
    line.start()
    try:
        plc = Plc(line.plc_port)
        conv = Conveyor(line.axis_port) if conveyor else None
        p = run_part(plc, conv, 1, PART_ID, timeout=60)
        plc.close()
        if conv:
            conv.close()
    finally:
        rcs = line.stop()
    assert rcs.get("hotgauged") == 0, rcs
    assert p["state"] == DONE, f"part not DONE: {p}"
    jsonl = glob.glob(os.path.join(line.results_dir, "*.jsonl"))
    result = json.loads(open(jsonl[0]).read().splitlines()[-1])
    rec = glob.glob(os.path.join(line.archive_dir, "*", f"*_{PART_ID}"))
    assert len(rec) == 1, f"archive: {rec}"
    return result, rec[0]


def features(result):
    return {f["name"]: f for f in result["features"]}


def compare(label, got, want):
    """Largest |difference| of hot and cold values, µm; fails on verdicts or a value's presence."""
    g, w = features(got), features(want)
    assert g.keys() == w.keys(), f"{label}: features {sorted(g)} vs {sorted(w)}"
    worst = 0.0
    for name, f in w.items():
        for key in ("hot_mm", "cold_mm"):
            a, b = g[name][key], f[key]
            assert (a is None) == (b is None), f"{label}: {name} {key} {a} vs {b}"
            if a is not None:
                worst = max(worst, abs(a - b) * 1e3)
        assert g[name]["verdict"] == f["verdict"], \
            f"{label}: {name} verdict {g[name]['verdict']} vs {f['verdict']}"
    assert got["verdict"] == want["verdict"], f"{label}: {got['verdict']} vs {want['verdict']}"
    print(f"{label}: {len(w)} features, verdict {got['verdict']}, largest difference "
          f"{worst:.6f} µm")
    assert worst <= TOLERANCE_UM, f"{label}: {worst:.4f} µm > {TOLERANCE_UM} µm"
    return worst


def compare_recordings(original, replayed):
    """The replayed recording against the original: profiles and positions bit for bit, each
    face's profile and accelerometer times shifted by one offset, the samples the same."""
    faces = yaml.safe_load(open(os.path.join(original, "part.yaml")))["faces"]
    assert yaml.safe_load(open(os.path.join(replayed, "part.yaml")))["faces"] == faces
    for face in faces:
        a, b = (os.path.join(d, face) for d in (original, replayed))
        load = lambda d, n: np.load(os.path.join(d, n))  # noqa: E731
        for n in ("profiles.npy", "profile_positions.npy", "accel.npy"):
            assert load(a, n).tobytes() == load(b, n).tobytes(), f"{face}/{n} differs"
        dt = load(b, "profile_times.npy") - load(a, "profile_times.npy")
        da = load(b, "accel_times.npy") - load(a, "accel_times.npy")
        assert len(set(dt)) == 1 and set(da) == set(dt), f"{face}: times not shifted as one"
    print(f"replayed recording: {len(faces)} faces, profiles, positions and accelerometer "
          f"samples bit for bit, times shifted by one offset per face")


def bad_input(bin_dir, workdir, cal, rec):
    """An unreadable recording stops the cell at start, naming the file; a face the recording
    lacks is no frame at all: the daemon's part fails with fault 203, the cell's log names the
    recording and the face."""
    r = subprocess.run([os.path.join(bin_dir, "src/app/hotgauge"), "simulate", "--serve",
                        "--mode", "peaks", "--address", REPLAY_ADDRESS, "--seconds", "5",
                        "--replay", os.path.join(workdir, "nothing"), "--calibration", cal],
                       capture_output=True, text=True, timeout=60)
    want = os.path.join(workdir, "nothing", "part.yaml") + ": missing"
    assert r.returncode == 1 and want in r.stderr, (r.returncode, r.stderr)
    unreadable = next(l for l in r.stderr.splitlines() if want in l)
    three = os.path.join(workdir, "three-faces")
    shutil.copytree(rec, three)
    shutil.rmtree(os.path.join(three, "side2"))
    part = yaml.safe_load(open(os.path.join(three, "part.yaml")))
    part["faces"].remove("side2")
    with open(os.path.join(three, "part.yaml"), "w") as f:
        yaml.safe_dump(part, f)
    d = os.path.join(workdir, "missing-face")
    os.makedirs(d)
    line = ReplayLine(bin_dir, d, REPLAY_ADDRESS, calibration=cal, recording=three).start()
    try:
        plc = Plc(line.plc_port)
        plc.trigger(PART_ID + 1, face=4)  # side2 only
        r = decode(plc.wait_state({DONE, FAULT}, 30))
        plc.close()
    finally:
        line.stop()
    assert r["state"] == FAULT and r["error"] == 203, r
    log = open(os.path.join(d, "virtual-cell.log")).read()
    want = f"{three}/part.yaml: face 'side2' is not in the recording"
    assert want in log, log[-2000:]
    print(f"bad input: an unreadable recording stops the cell ({unreadable.strip()}); a "
          f"missing face sends no frame and the part fails with fault {r['error']}")


def archived_part(bin_dir, workdir):
    """Steps 1-3 of the module docstring and the bad input; returns the largest difference, µm."""
    cal = shifted_calibration(os.path.join(workdir, "calibration.yaml"))
    first = os.path.join(workdir, "line")
    os.makedirs(first)
    line = Line(bin_dir, first, ADDRESS, calibration=cal, true_calibration=cal,
                archive_every_nth_ok=1, config_extra=PIPELINE)
    result, rec = one_part(line)
    print(f"archived by the line: {rec} ({result['part']['verdict']})")
    second = os.path.join(workdir, "replay")
    os.makedirs(second)
    replay = ReplayLine(bin_dir, second, REPLAY_ADDRESS, calibration=cal,
                        archive_every_nth_ok=1, recording=rec, lose_first_start=True,
                        config_extra=PIPELINE)
    replayed, rec2 = one_part(replay, conveyor=False)
    daemon_log = open(os.path.join(second, "hotgauged.log")).read()
    assert daemon_log.count("the scan lost its start") == 1 and "scanning it again" in daemon_log, \
        "the replay's first scan was to lose its start once"
    offline = json.loads(hotgauge(bin_dir, "measure", rec, "--calibration", cal, "--json",
                                  *MEASURE_OPTIONS))
    again = json.loads(hotgauge(bin_dir, "measure", rec2, "--calibration", cal, "--json",
                                *MEASURE_OPTIONS))
    default = json.loads(hotgauge(bin_dir, "measure", rec, "--calibration", cal, "--json"))
    moved = max(abs(a["cold_mm"] - b["cold_mm"]) * 1e3
                for a, b in zip(offline["features"], default["features"])
                if a["cold_mm"] is not None and b["cold_mm"] is not None)
    print(f"the daemon's pipeline settings ({PIPELINE.strip()}) are the tool's "
          f"{' '.join(MEASURE_OPTIONS)}: with the default corner the features move by up to "
          f"{moved:.3f} µm")
    assert moved > 0.01, "the high-pass corner changed nothing: the comparison proves nothing"
    worst = max(compare("line's result vs measure of its archive", result["part"], offline),
                compare("replay's result vs measure of the original", replayed["part"], offline),
                compare("measure of the replay's archive vs the original", again, offline))
    compare_recordings(rec, rec2)
    cell_log = open(os.path.join(second, "virtual-cell.log")).read()
    print(next(l for l in cell_log.splitlines() if l.startswith("replayed ")))
    assert " 0 not " in cell_log, "profiles that did not go out exactly as peaks"
    ahead = [l for l in cell_log.splitlines() if "its record follows the one sent before" in l]
    assert ahead, "the face scanned again did not follow its first record"
    print("scanned again after a lost start: " + ahead[0].split("replay: ")[1])
    bad_input(bin_dir, workdir, cal, rec)
    return worst


def trim_to_daemon(rec, margin_s=0.51, profiles_per_frame=10):
    """What the daemon would have kept of a recording that did not come from it: whole frames,
    and the accelerometer window [first − margin, last + margin) (its margin_s + 10 ms slack)."""
    m = int(margin_s * 1e9)
    for face in yaml.safe_load(open(os.path.join(rec, "part.yaml")))["faces"]:
        path = lambda n: os.path.join(rec, face, n)  # noqa: E731
        t = np.load(path("profile_times.npy"))
        n = len(t) // profiles_per_frame * profiles_per_frame
        for name in ("profiles.npy", "profile_times.npy", "profile_positions.npy"):
            np.save(path(name), np.load(path(name))[:n])
        a = np.load(path("accel_times.npy"))
        keep = (a >= t[0] - m) & (a < t[n - 1] + m)
        np.save(path("accel_times.npy"), a[keep])
        np.save(path("accel.npy"), np.load(path("accel.npy"))[keep])


def off_grid(bin_dir, workdir, seed):
    """A recording whose profiles are not on the peak format's grid (the offline simulator's
    floats, as from a camera in image mode): what the format's 1/64 px does to the features."""
    rec = os.path.join(workdir, "simulated")
    hotgauge(bin_dir, "simulate", "--out", rec, "--seed", str(seed), "--temperature", "1050")
    trim_to_daemon(rec)
    d = os.path.join(workdir, "replay-simulated")
    os.makedirs(d)
    replayed, _ = one_part(ReplayLine(bin_dir, d, REPLAY_ADDRESS, calibration=NOMINAL,
                                      archive_every_nth_ok=1, recording=rec), conveyor=False)
    offline = json.loads(hotgauge(bin_dir, "measure", rec, "--calibration", NOMINAL, "--json"))
    cell_log = open(os.path.join(d, "virtual-cell.log")).read()
    print(next(l for l in cell_log.splitlines() if l.startswith("replayed ")))
    return compare(f"simulated part (seed {seed}) replayed vs measured", replayed["part"], offline)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("bin_dir")
    ap.add_argument("--off-grid", type=int, metavar="SEED",
                    help="instead: replay a simulated recording off the peak grid (quantisation)")
    a = ap.parse_args()
    bin_dir = os.path.abspath(a.bin_dir)
    workdir = tempfile.mkdtemp(prefix="hotgauge-replay-")
    ok = False
    t0 = time.monotonic()
    try:
        worst = off_grid(bin_dir, workdir, a.off_grid) if a.off_grid is not None else \
            archived_part(bin_dir, workdir)
        print(f"replay: largest feature difference {worst:.6f} µm; "
              f"{time.monotonic() - t0:.0f} s")
        ok = True
    finally:
        if not ok:
            for d in sorted(os.listdir(workdir)):
                if os.path.exists(os.path.join(workdir, d, "hotgauged.log")):
                    print(f"=== {d} ===")
                    print_logs(os.path.join(workdir, d))
        else:
            shutil.rmtree(workdir, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
