"""Benchmark: incremental vs naive per-contact map update (``scripts/bench.sh gpis``).

For each mode (2D lattice 128^2, 3D lattice 48^3) contacts sampled on a circle/sphere
(seeded) are added one at a time through ``ShapeEstimator`` (default YAML parameters,
value observations; ``--normals`` adds gradient rows). At n = 50, 200, 500 it times

- incremental: ``add_observation`` of one more contact (Cholesky append + V row block,
  mean and variance over the whole lattice updated), median over ``--reps`` contacts;
- naive: ``GPIS.refit`` (full Cholesky + V = L^-1 K(X, M) from scratch + mean/variance),

and prints per-contact milliseconds and their ratio, measured in this one run.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from .estimator import ShapeEstimator

GOAL_RATIO = 20.0
GOAL_MS = 100.0


def contacts_on_sphere(rng: np.random.Generator, n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """n points (N, 3) and unit normals on a circle (2D, z = 0.06) / sphere around (0.5, 0, 0.1)."""
    d = rng.normal(size=(n, dim))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    centre = np.array([0.5, 0.0, 0.1])[:dim]
    p = centre + 0.05 * d
    if dim == 2:
        p = np.column_stack([p, np.full(n, 0.06)])
        d = np.column_stack([d, np.zeros(n)])
    return p, d


def run(dim: int, ns: list[int], reps: int, naive_reps: int, normals: bool, seed: int) -> list[dict]:
    est = ShapeEstimator.from_params({"mode": f"{dim}d", "use_normals": normals, "duplicate_distance_m": 0.0})
    M = int(np.prod(est.lattice_shape))
    rng = np.random.default_rng(seed)
    pts, nrm = contacts_on_sphere(rng, max(ns) + reps + 1, dim)
    i = 0
    records = []
    for n in ns:
        while est.n_observations < n:
            est.add_observation(pts[i], nrm[i], 1)
            i += 1
        times = []
        for _ in range(reps):
            t0 = time.perf_counter()
            ok, why = est.add_observation(pts[i], nrm[i], 1)
            times.append(time.perf_counter() - t0)
            if not ok:
                raise RuntimeError(why)
            i += 1
        inc_ms = 1e3 * float(np.median(times))
        mean_inc, var_inc = est.gp.eval_mean(), est.gp.eval_variance()
        naive = []
        for _ in range(naive_reps if n >= 200 else max(naive_reps, 3)):
            t0 = time.perf_counter()
            est.gp.refit()
            naive.append(time.perf_counter() - t0)
        naive_ms = 1e3 * float(np.median(naive))
        err = max(np.abs(est.gp.eval_mean() - mean_inc).max(), np.abs(est.gp.eval_variance() - var_inc).max())
        rec = {"dim": dim, "n": n, "M": M, "incremental_ms": round(inc_ms, 3), "naive_ms": round(naive_ms, 3),
               "ratio": round(naive_ms / inc_ms, 2), "rows": int(est.gp.n), "max_abs_diff": float(err)}
        records.append(rec)
        print(f"{dim}D  n={n:4d}  M={M:7d}  incremental {inc_ms:9.2f} ms   naive {naive_ms:10.2f} ms   "
              f"ratio {naive_ms / inc_ms:7.1f}x   |incr - naive| {err:.1e}", flush=True)
    return records


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", metavar="FILE", help="also write the figures as a JSON list of records")
    ap.add_argument("--ns", type=int, nargs="+", default=[50, 200, 500], help="contact counts")
    ap.add_argument("--dims", type=int, nargs="+", default=[2, 3], choices=[2, 3])
    ap.add_argument("--reps", type=int, default=5, help="incremental contacts timed per n (median)")
    ap.add_argument("--naive-reps", type=int, default=1, help="naive refits timed per n >= 200 (median)")
    ap.add_argument("--normals", action="store_true", help="contacts carry normals (1 + dim rows each)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    records = []
    for dim in args.dims:
        records += run(dim, sorted(args.ns), args.reps, args.naive_reps, args.normals, args.seed)
    goal = [r for r in records if r["dim"] == 3 and r["n"] == 200]
    if goal:
        r = goal[0]
        met = r["ratio"] >= GOAL_RATIO and r["incremental_ms"] < GOAL_MS
        print(f"goal (3D, n=200, M={r['M']}): ratio >= {GOAL_RATIO:.0f}x and < {GOAL_MS:.0f} ms: "
              f"{r['ratio']:.1f}x, {r['incremental_ms']:.1f} ms -> {'MET' if met else 'NOT MET'}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(records, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
