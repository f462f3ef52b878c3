#!/usr/bin/python3
"""Reference values for measure::between_std from statsmodels (an oracle nobody here wrote).

statsmodels' combine_effects(..., method_re="dl") is the DerSimonian-Laird random-effects
estimator; its tau2 is the between-value variance that between_std returns the root of. This
version does not truncate a negative estimate (values that agree better than their
uncertainties say); the file keeps it as statsmodels gives it, and the test compares
sqrt(max(0, tau2)), the usual truncation. The cases are fixed by a seeded generator, so the file is reproducible:

    make oracle-refs    # installs python3-statsmodels (ORACLE_PACKAGES), rewrites the file

writes data/oracle/random-effects-dl.json, read by tests/test_fit.cpp.
"""
import json
import pathlib
import sys
import warnings

import numpy as np
import statsmodels
from statsmodels.stats.meta_analysis import combine_effects


def cases():
    rng = np.random.default_rng(20261204)
    # Shapes of what the measurement feeds it: sector heights (mm) with per-sector u, a few to
    # a dozen sectors; agreeing values, a true spread, one far-off sector with a wide u (the
    # case that made the plain spread wrong), and widely unequal uncertainties.
    for i in range(24):
        k = int(rng.integers(2, 13))
        u = rng.uniform(0.001, 0.02, k)
        tau = [0.0, 0.002, 0.01, 0.05][i % 4]
        v = 40.0 + rng.normal(0.0, 1.0, k) * np.sqrt(u**2 + tau**2)
        if i % 6 == 5:
            v[0] += 0.06
            u[0] = 0.038
        if i % 5 == 4:
            u[-1] = 1e-4
        yield f"seeded-{i:02d}", v, u
    yield "two-equal", np.array([1.0, 1.0]), np.array([0.01, 0.01])
    yield "two-apart", np.array([1.0, 1.1]), np.array([0.01, 0.01])


def main():
    out = {
        "generator": "tests/oracle/make_dl_reference.py",
        "oracle": f"statsmodels {statsmodels.__version__} combine_effects(method_re='dl').tau2",
        "cases": [],
    }
    for name, v, u in cases():
        with warnings.catch_warnings():  # its other outputs (I², HKSJ) for a negative tau2
            warnings.simplefilter("ignore", RuntimeWarning)
            res = combine_effects(v, u**2, method_re="dl")
        out["cases"].append({"name": name, "values": v.tolist(), "u": u.tolist(),
                             "tau2": float(res.tau2)})
    path = pathlib.Path(__file__).resolve().parents[2] / "data/oracle/random-effects-dl.json"
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(f"{path}: {len(out['cases'])} cases", file=sys.stderr)


if __name__ == "__main__":
    main()
