"""Independent dense GP reference for the tests: explicit loops over observation pairs,
analytic kernel derivatives written out per kernel, numpy.linalg.solve (no Cholesky)."""

from __future__ import annotations

import numpy as np


def radial_derivs(kind: str, r: float, R: float = 1.0, ell: float = 0.3, s2: float = 1.0):
    """k(r), k'(r), k''(r) of each kernel, written out independently."""
    if kind == "thin_plate":
        return 2 * r**3 - 3 * R * r**2 + R**3, 6 * r**2 - 6 * R * r, 12 * r - 6 * R
    if kind == "squared_exponential":
        k = s2 * np.exp(-r * r / (2 * ell * ell))
        return k, -r / ell**2 * k, (r * r / ell**4 - 1 / ell**2) * k
    if kind == "matern52":
        a = np.sqrt(5) / ell
        e = np.exp(-a * r)
        k = s2 * (1 + a * r + a * a * r * r / 3) * e
        d1 = -s2 * a * a * r * (1 + a * r) / 3 * e
        d2 = -s2 * a * a / 3 * (1 + a * r - a * a * r * r) * e
        return k, d1, d2
    raise ValueError(kind)


def cov(kind, xa, ta, xb, tb, **kw) -> float:
    """Covariance of observation (xa, ta) and (xb, tb); t = -1 value, i = d/dx_i."""
    u = xa - xb
    r = float(np.linalg.norm(u))
    k, d1, d2 = radial_derivs(kind, r, **kw)
    if ta < 0 and tb < 0:
        return k
    if r == 0:
        # d2k/dx_i dy_j at r = 0: -k''(0) delta_ij; value-gradient: 0
        if ta >= 0 and tb >= 0:
            return -d2 * (ta == tb) if kind != "thin_plate" else 6 * kw.get("R", 1.0) * (ta == tb)
        return 0.0
    uh = u / r
    if ta >= 0 and tb < 0:  # d/dx_i k = k' u_i / r
        return d1 * uh[ta]
    if ta < 0 and tb >= 0:  # d/dy_j k = -k' u_j / r
        return -d1 * uh[tb]
    # d2/dx_i dy_j k(|x-y|) = -[k'' uh_i uh_j + k'/r (delta_ij - uh_i uh_j)]
    i, j = ta, tb
    return -(d2 * uh[i] * uh[j] + d1 / r * ((i == j) - uh[i] * uh[j]))


def dense_posterior(kind, X, t, y, noise, Xq, tq, mean_fn=None, **kw):
    """Posterior mean and variance at query rows, by dense solves."""
    n, m = len(X), len(Xq)
    K = np.array([[cov(kind, X[a], t[a], X[b], t[b], **kw) for b in range(n)] for a in range(n)])
    K += np.diag(noise)
    Ks = np.array([[cov(kind, X[a], t[a], Xq[b], tq[b], **kw) for b in range(m)] for a in range(n)])
    kqq = np.array([cov(kind, Xq[b], tq[b], Xq[b], tq[b], **kw) for b in range(m)])
    my = np.zeros(n) if mean_fn is None else mean_fn(X, t)
    mq = np.zeros(m) if mean_fn is None else mean_fn(Xq, tq)
    alpha = np.linalg.solve(K, y - my)
    mean = mq + Ks.T @ alpha
    var = kqq - np.einsum("ij,ij->j", Ks, np.linalg.solve(K, Ks))
    return mean, var
