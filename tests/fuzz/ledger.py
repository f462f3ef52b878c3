#!/usr/bin/python3
"""What the fuzzing runs of tests/fuzz/ledger.tsv add up to for the readers of a commit
(tests/fuzz/README.md "Runs that add up"). A run counts for a harness when the files its reader is
made of are the same at the run's commit as at the commit asked about (HEAD by default): a change
to a reader starts its count again. Runs made on a tree with changes (+dirty) or with a binary
older than the sources (+stale) never count.

    tests/fuzz/ledger.py [--commit REV] [--goal N]     exit 1 when a harness is under the goal
"""
import argparse
import collections
import os
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))

# The files each harness's reader is made of, besides the harness itself and fuzz_util.hpp.
# read_bytes (bytes.cpp) is not among them: the harnesses pass their input's bytes.
COMMON_YAML = ["src/io/yaml_reader.cpp", "include/hotgauge/io/yaml_reader.hpp",
               "include/hotgauge/io/bytes.hpp", "src/core/geometry.cpp"]
READERS = {
    "fuzz_npy": ["src/io/npy.cpp", "include/hotgauge/io/npy.hpp", "include/hotgauge/io/bytes.hpp"],
    "fuzz_recording": COMMON_YAML + ["src/io/recording_io.cpp", "include/hotgauge/io/recording_io.hpp",
                                     "src/io/npy.cpp", "src/io/yaml_writer.cpp",
                                     "include/hotgauge/core/recording.hpp"],
    "fuzz_recipe": COMMON_YAML + ["src/io/recipe.cpp", "include/hotgauge/io/recipe.hpp",
                                  "include/hotgauge/core/part.hpp", "src/core/part.cpp"],
    "fuzz_certificate": COMMON_YAML + ["src/io/certificate.cpp", "include/hotgauge/core/master.hpp"],
    "fuzz_calibration": COMMON_YAML + ["src/calib/calibration.cpp", "src/calib/sensor.cpp",
                                       "include/hotgauge/calib/calibration.hpp",
                                       "include/hotgauge/calib/sensor.hpp"],
    "fuzz_artifact": COMMON_YAML + ["src/calib/artifact.cpp", "include/hotgauge/calib/artifact.hpp"],
    "fuzz_daemon_config": COMMON_YAML + ["src/cell/config.cpp", "src/cell/plc_sections.cpp",
                                         "include/hotgauge/cell/config.hpp", "src/accel/source.cpp",
                                         "src/plant/mqtt.cpp"],
    "fuzz_results": ["src/results/read_back.cpp", "include/hotgauge/results/read_back.hpp",
                     "src/report/lot_report.cpp", "src/report/lot_html.cpp", "src/report/aqdef.cpp",
                     "src/report/html.cpp", "include/hotgauge/report/html.hpp",
                     "src/core/text.cpp", "include/hotgauge/core/text.hpp"],
    "fuzz_model": ["src/model/model_io.cpp", "include/hotgauge/model/model_io.hpp", "src/match/model.cpp",
                   "include/hotgauge/match/model.hpp", "include/hotgauge/io/checksum.hpp"],
    "fuzz_modbus": ["src/plc/modbus_tcp.cpp", "include/hotgauge/plc/modbus_tcp.hpp"],
}


def git(*args):
    return subprocess.run(["git", "-C", REPO, *args], capture_output=True, text=True)


def same_reader(harness, run_commit, commit, cache):
    key = (harness, run_commit)
    if key not in cache:
        files = READERS.get(harness, []) + ["tests/fuzz/%s.cpp" % harness, "tests/fuzz/fuzz_util.hpp"]
        diff = git("diff", "--quiet", run_commit, commit, "--", *files)
        if diff.returncode > 1:
            print("ledger.py: commit %s of a %s run: %s" % (run_commit, harness, diff.stderr.strip()),
                  file=sys.stderr)
        cache[key] = diff.returncode == 0
    return cache[key]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--commit", default="HEAD")
    ap.add_argument("--goal", type=float, default=1e7)
    args = ap.parse_args()
    total = collections.Counter()
    seconds = collections.Counter()
    findings = collections.Counter()
    cache = {}
    path = os.path.join(HERE, "ledger.tsv")
    rows = list(open(path))[1:] if os.path.exists(path) else []
    for row in rows:
        date, harness, commit, runs, secs, found = row.rstrip("\n").split("\t")
        if "+" in commit or not same_reader(harness, commit, args.commit, cache):
            continue
        total[harness] += int(runs)
        seconds[harness] += float(secs)
        findings[harness] += int(found)
    short = False
    print("%-20s %14s %10s %9s" % ("harness", "executions", "seconds", "findings"))
    for harness in sorted(os.listdir(os.path.join(HERE, "corpus"))):
        mark = "" if total[harness] >= args.goal else "  < %.0e" % args.goal
        short = short or bool(mark) or findings[harness] > 0
        print("%-20s %14d %10.0f %9d%s" % (harness, total[harness], seconds[harness],
                                          findings[harness], mark))
    return 1 if short else 0


if __name__ == "__main__":
    sys.exit(main())
