#!/usr/bin/env python3
"""Generates the Lasso-vs-scikit-learn fixture under emulator/tests/data/lasso_fixture/.

Inputs (x.csv, y.csv) and scikit-learn's answers (expected.json) are committed; the Rust
test `lasso_matches_sklearn` needs no Python. The design mimics the surrogate's: lagged,
strongly correlated columns of two slow signals, plus a couple of unrelated ones.

    pip install scikit-learn numpy && python3 tools/gen_lasso_fixture.py
"""
import json
import os

import numpy as np
import sklearn
from sklearn.linear_model import Lasso

OUT = os.path.join(os.path.dirname(__file__), "..", "emulator", "tests", "data", "lasso_fixture")
ALPHAS = [0.3, 0.03, 0.003, 0.0003]
TOL = 1e-10

rng = np.random.default_rng(20240607)
n = 240
t = np.arange(n + 4) * 0.25
u = np.sin(1.3 * t) + 0.3 * np.sin(3.1 * t + 0.4) + 0.05 * rng.standard_normal(n + 4)
v = np.cos(0.7 * t) * 400.0 + 500.0
cols = [u[4 - k : n + 4 - k] for k in range(4)]  # u[t], u[t-1] .. u[t-3]
cols += [v[4 - k : n + 4 - k] for k in range(3)]  # v[t] .. v[t-2]
cols += [rng.standard_normal(n), rng.uniform(-2.0, 2.0, n)]
cols += [cols[0] * cols[4] / 500.0, cols[1] ** 2]
x = np.column_stack(cols)
y = 1.5 * x[:, 0] - 0.7 * x[:, 2] + 0.002 * x[:, 4] + 0.8 * x[:, 9] + 10.0
y += 0.05 * rng.standard_normal(n)

os.makedirs(OUT, exist_ok=True)
np.savetxt(os.path.join(OUT, "x.csv"), x, delimiter=",", fmt="%.17g")
np.savetxt(os.path.join(OUT, "y.csv"), y, delimiter=",", fmt="%.17g")
fits = []
for a in ALPHAS:
    m = Lasso(alpha=a, fit_intercept=True, precompute=True, tol=TOL, max_iter=10_000_000)
    m.fit(x, y)
    fits.append({"alpha": a, "coef": [float(c) for c in m.coef_],
                 "intercept": float(m.intercept_), "n_iter": int(m.n_iter_)})
with open(os.path.join(OUT, "expected.json"), "w") as f:
    json.dump({"generator": "tools/gen_lasso_fixture.py", "sklearn": sklearn.__version__,
               "tol": TOL, "fit_intercept": True, "precompute": True, "fits": fits}, f, indent=1)
print("wrote", OUT)
