#!/usr/bin/python3
"""Sorting as-forged parts (issue 36): random hub-a forgings from our simulator (drafts, fillets,
die shift, scattered dimensions, press vibration, 700-1300 °C), some with a feature out of
tolerance, through `hotgauge measure` as the cell runs it (the part found by matching). Per
feature: the error against the truth at the sharp corners, the k = 2 coverage of u, false OK (out
of tolerance by more than 2u, reported OK) and false NOK (inside by more than 2u, reported NOK).

  forged_sorting.py BUILD_DIR --parts 50 --first-seed 1000 [--bad-every 3] [--check]

--check asserts issue 36's rule: every measured feature within ±0.02 mm (Height 1 may be NOT
MEASURED with its reason), no false OK, no false NOK, coverage >= 95 %, every part measured.
--check-sorting asserts what holds on our simulator today (docs/measurement.md "Real forgings":
its top and bottom sensors lose a drafted wall at grazing incidence, and its range noise along
the ray biases the fillet fit): every part found, every feature but Height 1 measured, no false
OK, no false NOK, every value within ±0.05 mm (the fillet bias was 0.7-3.2 mm), or within 2u
where no face saw the wall (its draft from the drawing or from a step's two fillets); with
--min-coverage, at least that k = 2 coverage of u."""
import argparse
import concurrent.futures as cf
import json
import math
import os
import random
import shlex
import shutil
import subprocess
import sys
import tempfile

import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
RECIPE = os.path.join(HERE, "..", "..", "config", "parts", "hub-a.yaml")
LIMIT_MM = 0.02
GUARD_MM = 0.05  # --check-sorting


def bad_for(seed, recipe, every):
    """One feature out of tolerance on every `every`-th part: which and by how much (mm, cold)."""
    if every <= 0 or seed % every:
        return None
    rng = random.Random(seed)
    f = rng.choice([f for f in recipe["features"] if f["name"] != "Height 1"])
    lo, hi = f["tolerance_mm"]
    side = rng.choice([-1, 1]) if lo < 0 else 1
    beyond = rng.uniform(0.1, 0.8)
    return f["name"], (hi + beyond) if side > 0 else (lo - beyond)


def one_part(bin_dir, seed, bad, extra=()):
    hotgauge = os.path.join(bin_dir, "src", "app", "hotgauge")
    tmp = tempfile.mkdtemp(prefix=f"forged_{seed}_")
    try:
        rng = random.Random(seed)
        temp = rng.uniform(700.0, 1300.0)
        cmd = [hotgauge, "simulate", "--forged", "--out", f"{tmp}/part", "--seed", str(seed),
               "--temperature", f"{temp:.1f}", "--dimension-sigma", "0.07",
               "--t0-ns", str(1_790_000_000_000_000_000 + seed * 10**11)]
        if bad:
            cmd += ["--bad", f"{bad[0]}={bad[1]:+.4f}"]
        cmd += list(extra)
        subprocess.run(cmd, check=True, capture_output=True, text=True)
        truth = yaml.safe_load(open(f"{tmp}/part.truth/truth.yaml"))
        out = subprocess.run([hotgauge, "measure", f"{tmp}/part", "--json", "--threads", "1"],
                             check=True, capture_output=True, text=True)
        return seed, bad, truth, json.loads(out.stdout)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def judge(recipe, parts):
    spec = {f["name"]: f for f in recipe["features"]}
    rows = {n: {"err": [], "cover": 0, "false_ok": 0, "false_nok": 0, "nm": 0, "nm_reasons": []}
            for n in spec}
    problems = []
    for seed, bad, truth, res in parts:
        if res.get("match") and not res["match"].get("found", True):
            problems.append(f"seed {seed}: part not found: {res['match'].get('reason')}")
        t = {f["name"]: f for f in truth["features"]}
        for f in res["features"]:
            n, row = f["name"], rows[f["name"]]
            if f["hot_mm"] is None:
                row["nm"] += 1
                row["nm_reasons"].append(f"seed {seed}: {f['reason']}")
                if n != "Height 1":
                    problems.append(f"seed {seed}: {n} not measured: {f['reason']}")
                continue
            err = f["hot_mm"] - t[n]["hot_mm"]
            u = f["u_mm"] or 0.0
            row["err"].append(err)
            row["cover"] += abs(err) <= 2.0 * u
            if abs(err) > LIMIT_MM:
                unseen = "drawing" in f["method"] or "fillets" in f["method"]
                within = abs(err) <= GUARD_MM or (unseen and abs(err) <= 2 * u)
                kind = "beyond ±0.02 mm" if within else "off"
                problems.append(f"seed {seed}: {n} {kind}: {err:+.4f} mm (u {u:.4f}, {f['method']})")
            lo, hi = spec[n]["tolerance_mm"]
            dev = t[n]["cold_mm"] - spec[n]["nominal_mm"]
            margin = min(dev - lo, hi - dev)  # > 0 inside, < 0 outside (cold mm)
            u_cold = f.get("u_cold_mm") or u
            if margin < -2.0 * u_cold and f["verdict"] == "OK":
                row["false_ok"] += 1
                problems.append(f"seed {seed}: {n} FALSE OK (outside by {-margin:.3f} mm)")
            if margin > 2.0 * u_cold and f["verdict"] == "NOK":
                row["false_nok"] += 1
                problems.append(f"seed {seed}: {n} FALSE NOK (inside by {margin:.3f} mm)")
    return rows, problems


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("build_dir")
    ap.add_argument("--parts", type=int, default=50)
    ap.add_argument("--first-seed", type=int, default=1000)
    ap.add_argument("--bad-every", type=int, default=3, help="every N-th seed has a bad feature")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--check", action="store_true")
    ap.add_argument("--check-sorting", action="store_true")
    ap.add_argument("--min-coverage", type=float, default=0.0,
                    help="with --check-sorting: fail below this k = 2 coverage of u (0-1)")
    ap.add_argument("--simulate-args", default="",
                    help="more `hotgauge simulate` options, e.g. \"--noise 0 --no-vibration\"")
    ap.add_argument("--dump", help="write every measured feature (seed, error, u, method, u "
                    "budget) to this JSON-lines file")
    a = ap.parse_args()
    recipe = yaml.safe_load(open(RECIPE))
    seeds = range(a.first_seed, a.first_seed + a.parts)
    with cf.ThreadPoolExecutor(a.jobs) as ex:
        parts = list(ex.map(lambda s: one_part(a.build_dir, s, bad_for(s, recipe, a.bad_every),
                                             shlex.split(a.simulate_args)),
                            seeds))
    rows, problems = judge(recipe, parts)
    if a.dump:
        with open(a.dump, "w") as out:
            for seed, bad, truth, res in parts:
                t = {f["name"]: f for f in truth["features"]}
                for f in res["features"]:
                    out.write(json.dumps({
                        "seed": seed, "bad": bad and bad[0], "name": f["name"],
                        "err": f["hot_mm"] - t[f["name"]]["hot_mm"] if f["hot_mm"] else None,
                        "u": f["u_mm"], "method": f.get("method"),
                        "budget": f.get("u_budget_mm"), "n_points": f.get("n_points"),
                        "stage_ms": res.get("stage_ms")}) + "\n")
    n_bad = sum(1 for p in parts if p[1])
    print(f"{len(parts)} as-forged parts (seeds {seeds.start}-{seeds.stop - 1}), {n_bad} with a "
          f"bad feature; errors hot, mm, against the truth at the sharp corners")
    print(f"{'feature':16s} {'n':>3s} {'mean':>8s} {'rms':>7s} {'max|e|':>7s} {'cover':>6s} "
          f"{'falseOK':>7s} {'falseNOK':>8s} {'n/m':>4s}")
    n_all = covered = 0
    for n, r in rows.items():
        e = r["err"]
        if not e:
            print(f"{n:16s} {0:3d} {'':>8s} {'':>7s} {'':>7s} {'':>6s} {0:7d} {0:8d} {r['nm']:4d}")
            continue
        mean = sum(e) / len(e)
        rms = math.sqrt(sum(x * x for x in e) / len(e))
        n_all += len(e)
        covered += r["cover"]
        print(f"{n:16s} {len(e):3d} {mean:+8.4f} {rms:7.4f} {max(map(abs, e)):7.4f} "
              f"{100.0 * r['cover'] / len(e):5.1f}% {r['false_ok']:7d} {r['false_nok']:8d} "
              f"{r['nm']:4d}")
    coverage = covered / max(n_all, 1)
    print(f"k = 2 coverage of u over all measured features: {100 * coverage:.1f} % of {n_all}")
    for n, r in rows.items():
        for why in r["nm_reasons"][:2]:
            print(f"  not measured, {n}: {why}")
    for p in problems:
        print("PROBLEM:", p)
    if a.check and (problems or coverage < 0.95):
        print(f"FAILED: {len(problems)} problems, coverage {100 * coverage:.1f} %")
        sys.exit(1)
    hard = [p for p in problems if " beyond ±0.02 mm: " not in p]
    print(f"{len(problems) - len(hard)} values beyond ±{LIMIT_MM} mm of {n_all}, within "
          f"±{GUARD_MM} mm or 2u (a wall no face saw)")
    if a.check_sorting and (hard or coverage < a.min_coverage):
        print(f"FAILED: {len(hard)} problems, coverage {100 * coverage:.1f} % "
              f"(at least {100 * a.min_coverage:.0f} %)")
        sys.exit(1)


if __name__ == "__main__":
    main()
