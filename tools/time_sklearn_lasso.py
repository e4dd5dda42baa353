#!/usr/bin/env python3
"""Times scikit-learn's Lasso on the dataset `oils train --export-dataset DIR` wrote, on
the same problem our final fit solves: the paper model's features (features_n{N}.csv),
each column and each of the seven outputs standardised, coordinate descent with a
precomputed Gram matrix, one penalty `alpha = mu`, the same `tol`, cold start.

    oils train --export-dataset /tmp/ds --time-lasso   # prints n, mu and our timing
    python3 tools/time_sklearn_lasso.py /tmp/ds N MU [TOL] [MAX_ITER]

MAX_ITER (default 2000, scikit-learn's default is 1000) matters: if scikit-learn stops at
it without converging, its time is not comparable with a converged fit, so the script
says whether every output converged.
"""
import sys
import time

import numpy as np
from sklearn.linear_model import Lasso

d, n, mu = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
tol = float(sys.argv[4]) if len(sys.argv) > 4 else 1e-4
max_iter = int(sys.argv[5]) if len(sys.argv) > 5 else 2000
data = np.loadtxt(f"{d}/features_n{n}.csv", delimiter=",", skiprows=1)
x, y = data[:, : 11 * n + 10], data[:, 11 * n + 10 :]
sx = x.std(axis=0)
sx[sx == 0] = 1.0
sy = y.std(axis=0)
sy[sy == 0] = 1.0
xs, ys = (x - x.mean(axis=0)) / sx, (y - y.mean(axis=0)) / sy
best = []
for rep in range(5):
    t0 = time.perf_counter()
    # Gram once, as our fit does: X'X, then one coordinate descent per output.
    m = Lasso(alpha=mu, precompute=True, tol=tol, max_iter=max_iter, fit_intercept=True)
    m.fit(xs, ys)
    best.append(time.perf_counter() - t0)
print(f"sklearn Lasso(alpha={mu:g}, precompute=True, tol={tol:g}) on {x.shape[0]}x{x.shape[1]}, "
      f"{y.shape[1]} outputs: best of 5 {min(best):.4f} s (median {sorted(best)[2]:.4f} s)")
print("active per output:", [(int((c != 0).sum())) for c in np.atleast_2d(m.coef_)])
iters = np.atleast_1d(m.n_iter_)
print("iterations per output:", [int(i) for i in iters],
      "converged" if (iters < max_iter).all() else f"NOT converged (hit max_iter={max_iter})")
