#!/usr/bin/python3
"""Reference answers for the quality statistics (quality::capability, individuals_chart,
type1_study, type3_study), computed here with NumPy and statsmodels, not with our code:

- capability and control limits: NumPy (mean, ddof=1 std, np.diff moving ranges) with the
  published constants d2 = 1.128, D4 = 3.267;
- type-1 study: the bias's t and two-sided p from statsmodels' DescrStatsW.ttest_mean;
- type-3 study: the mean squares from statsmodels' anova_lm of ols("y ~ C(part)").

Data sets are seeded, so the file is reproducible:

    make oracle-refs    # installs python3-statsmodels (ORACLE_PACKAGES), rewrites the files

writes data/oracle/quality-statistics.json, read by tests/test_quality.cpp.
"""
import json
import math
import pathlib
import sys

import numpy as np
import pandas as pd
import statsmodels
import statsmodels.formula.api as smf
from statsmodels.stats.anova import anova_lm
from statsmodels.stats.weightstats import DescrStatsW

D2, D4 = 1.128, 3.267


def capability_case(name, x, lsl, usl):
    x = np.asarray(x, dtype=float)
    mean, s = x.mean(), x.std(ddof=1)
    mr = np.abs(np.diff(x)).mean()
    sw = mr / D2
    near = min(usl - mean, mean - lsl)
    return {"name": name, "values": x.tolist(), "lsl": lsl, "usl": usl,
            "mean": mean, "s_overall": s, "s_within": sw,
            "cp": (usl - lsl) / (6 * sw), "cpk": near / (3 * sw),
            "pp": (usl - lsl) / (6 * s), "ppk": near / (3 * s),
            "centre": mean, "lcl": mean - 3 * mr / D2, "ucl": mean + 3 * mr / D2,
            "mr_bar": mr, "mr_ucl": D4 * mr}


def type1_case(name, x, reference, tolerance, resolution):
    x = np.asarray(x, dtype=float)
    mean, s = x.mean(), x.std(ddof=1)
    t, p, _ = DescrStatsW(x).ttest_mean(reference)
    return {"name": name, "values": x.tolist(), "reference": reference, "tolerance": tolerance,
            "resolution": resolution, "mean": mean, "s": s, "bias": mean - reference,
            "cg": 0.2 * tolerance / (6 * s), "cgk": (0.1 * tolerance - abs(mean - reference)) / (3 * s),
            "t": float(t), "p_value": float(p), "resolution_share": resolution / tolerance}


def type3_case(name, by_part, tolerance):
    rows = [(f"p{i}", v) for i, part in enumerate(by_part) for v in part]
    df = pd.DataFrame(rows, columns=["part", "y"])
    table = anova_lm(smf.ols("y ~ C(part)", df).fit())
    ms_parts, ms_within = table["mean_sq"].iloc[0], table["mean_sq"].iloc[1]
    r = len(by_part[0])
    grr = math.sqrt(ms_within)
    pv = math.sqrt(max(0.0, (ms_parts - ms_within) / r))
    tv = math.hypot(grr, pv)
    return {"name": name, "by_part": [list(map(float, p)) for p in by_part],
            "tolerance": tolerance, "ms_parts": float(ms_parts), "ms_within": float(ms_within),
            "grr": grr, "pv": pv, "tv": tv, "grr_percent_tv": 100 * grr / tv,
            "grr_percent_tolerance": 100 * 6 * grr / tolerance,
            "ndc": int(math.floor(1.41 * pv / grr))}


def main():
    rng = np.random.default_rng(20261204)
    cap = [capability_case("centred", 69.5 + rng.normal(0, 0.02, 50), 69.2, 69.8),
           capability_case("off-centre", 69.62 + rng.normal(0, 0.03, 125), 69.2, 69.8),
           capability_case("drifting", 24.3 + np.linspace(0, 0.1, 40) + rng.normal(0, 0.01, 40),
                           24.0, 24.6),
           capability_case("two values", [1.0, 1.5], 0.0, 3.0)]
    t1 = [type1_case("unbiased", 48.3 + rng.normal(0, 0.002, 50), 48.3, 0.6, 0.0001),
          type1_case("biased", 48.3 + 0.004 + rng.normal(0, 0.002, 25), 48.3, 0.6, 0.001),
          type1_case("poor", 13.7 + rng.normal(0, 0.02, 30), 13.7, 0.6, 0.01)]
    t3 = [type3_case("10 parts x 3", [list(69.5 + d + rng.normal(0, 0.003, 3))
                                      for d in rng.normal(0, 0.05, 10)], 0.6),
          type3_case("5 parts x 2", [list(24.3 + d + rng.normal(0, 0.01, 2))
                                     for d in rng.normal(0, 0.02, 5)], 0.6),
          type3_case("parts alike", [list(13.7 + rng.normal(0, 0.01, 4)) for _ in range(6)], 0.6)]
    out = {"generator": "tests/oracle/make_quality_reference.py",
           "oracle": f"NumPy {np.__version__}, statsmodels {statsmodels.__version__} "
                     "(DescrStatsW.ttest_mean, anova_lm)",
           "capability": cap, "type1": t1, "type3": t3}
    path = pathlib.Path(__file__).resolve().parents[2] / "data/oracle/quality-statistics.json"
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(f"{path}: {len(cap)} + {len(t1)} + {len(t3)} cases", file=sys.stderr)


if __name__ == "__main__":
    main()
