"""Benchmark: per-contact map update of the exact and the scalable GPIS paths
(``scripts/bench.sh gpis``).

Contacts are sampled (seeded) on a 5 cm circle (2D, 128^2 lattice) / sphere (3D, 48^3)
and added one at a time through ``ShapeEstimator`` (default YAML parameters).

- ``method: exact`` records (``--ns``, default 50, 200, 500; value rows unless
  ``--normals``): incremental = median ``add_observation`` of ``--reps`` more contacts at n
  (Cholesky append + V row block, mean and variance over the whole lattice); naive =
  ``GPIS.refit`` (full Cholesky + V from scratch); ratio = naive / incremental.
- ``method: local`` records (``--local-ns``, default 200, 1000, 2000; always with normals):
  incremental = median ``add_observation`` of ``--local-reps`` more contacts; naive = one
  dense exact solve of the same rows (Cholesky of K(X, X) + mean at the lattice nodes next
  to the zero level set + variance at the candidates: the least an exact update must do
  for the decision); ratio = naive / incremental. level_set_error_m = max over those
  nodes of |mu_local - mu_exact| / |grad mu_exact| (the displacement of the zero level
  set); candidate_var_rel_error = max over the candidates of |var - var_exact| / var_exact.
  map_ms = median ``map_array`` (level set, candidates, their mean/variance/normal).

Each (method, dim, n) runs in its own process, so peak_rss_mb (the process's peak
resident memory, read before the dense reference is built) is that case's alone;
state_mb is what the local estimator holds (factors, caches, rows). *_cpu_ms are
process CPU times (less sensitive than wall times to the load of a shared machine).
All ratios are measured in this one run.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy: small solves lose to BLAS threads on a loaded machine

import argparse  # noqa: E402
import json  # noqa: E402
import multiprocessing as mp  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.linalg import solve_triangular  # noqa: E402

from .estimator import ShapeEstimator  # noqa: E402
from .gp import VALUE, cross_cov, gradient_rows  # noqa: E402

GOAL_RATIO = 20.0
GOAL_MS = 100.0
#: issue 14: per-contact update goals (ms) of the scalable path, 3D and 2D with normals
LOCAL_GOALS_MS = {(3, 1000): 20.0, (3, 2000): 40.0, (2, 2000): 5.0}
LEVEL_SET_GOAL_M = 0.5e-3



def _timed_contact(est, point, normal) -> tuple[float, float]:
    """Add one contact; its (wall s, CPU s). A contact the estimator refuses ends the benchmark."""
    t0, c0 = time.perf_counter(), time.process_time()
    ok, why = est.add_observation(point, normal, 1)
    wall_s, cpu_s = time.perf_counter() - t0, time.process_time() - c0
    if not ok:
        raise RuntimeError(why)
    return wall_s, cpu_s

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


def peak_rss_mb() -> float:
    """Peak resident memory of this process (MB; Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run(dim: int, ns: list[int], reps: int, naive_reps: int, normals: bool, seed: int) -> list[dict]:
    """The exact path: incremental vs naive refit (as before issue 14)."""
    est = ShapeEstimator.from_params({"mode": f"{dim}d", "use_normals": normals, "duplicate_distance_m": 0.0})
    M = int(np.prod(est.lattice_shape))
    rng = np.random.default_rng(seed)
    pts, nrm = contacts_on_sphere(rng, max(ns) + reps * len(ns) + 1, dim)
    i = 0
    records = []
    for n in ns:
        while est.n_observations < n:
            est.add_observation(pts[i], nrm[i], 1)
            i += 1
        times, cpu = [], []
        for _ in range(reps):
            wall_s, cpu_s = _timed_contact(est, pts[i], nrm[i])
            times.append(wall_s)
            cpu.append(cpu_s)
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
               "ratio": round(naive_ms / inc_ms, 2), "normals": normals, "method": "exact",
               "level_set_error_m": 0.0, "candidate_var_rel_error": 0.0,  # the exact path is the reference
               "incremental_cpu_ms": round(1e3 * float(np.median(cpu)), 3),
               "rows": int(est.gp.n), "max_abs_diff": float(err), "peak_rss_mb": round(peak_rss_mb(), 1)}
        records.append(rec)
        print(f"exact {dim}D  n={n:4d}  M={M:7d}  normals={normals!s:5}  incremental {inc_ms:9.2f} ms   "
              f"naive {naive_ms:10.2f} ms   ratio {naive_ms / inc_ms:7.1f}x   |incr - naive| {err:.1e}   "
              f"peak RSS {rec['peak_rss_mb']:.0f} MB", flush=True)
    return records


class DenseReference:
    """The exact posterior of an estimator's observations by one dense Cholesky."""

    def __init__(self, est: ShapeEstimator) -> None:
        X, t, y, nv = [], [], [], []
        for x, value, var, normal, normal_var in est._obs:
            X.append(x[None])
            t.append([VALUE])
            y.append([value])
            nv.append([var])
            if normal is not None:
                Xg, tg = gradient_rows(x[None])
                X += [Xg]
                t += [tg]
                y += [normal]
                nv += [np.full(est.dim, normal_var)]
        self.X, self.t = np.vstack(X), np.concatenate(t)
        self.kernel, self.mean_fn, self.dim = est.kernel, est.gp.mean_fn, est.dim
        mv, mg = self.mean_fn(self.X)
        prior = np.where(self.t < 0, mv, mg[np.arange(len(self.t)), np.maximum(self.t, 0)])
        K = cross_cov(self.kernel, self.X, self.t, self.X, self.t)
        K[np.diag_indices_from(K)] += np.concatenate(nv) + est.gp.jitter
        self.L = np.linalg.cholesky(K)
        self.alpha = solve_triangular(self.L.T, solve_triangular(self.L, np.concatenate(y) - prior, lower=True))

    def mean_grad(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Xg, tg = gradient_rows(Q)
        K = cross_cov(self.kernel, np.vstack([Q, Xg]), np.r_[np.full(len(Q), VALUE), tg], self.X, self.t)
        mv, mg = self.mean_fn(Q)
        f = K @ self.alpha
        return mv + f[: len(Q)], mg + f[len(Q):].reshape(len(Q), self.dim)

    def variance(self, Q: np.ndarray) -> np.ndarray:
        W = solve_triangular(self.L, cross_cov(self.kernel, self.X, self.t, Q, np.full(len(Q), VALUE)), lower=True)
        return self.kernel.k0 - np.einsum("ij,ij->j", W, W)


def crossing_nodes(mean: np.ndarray) -> np.ndarray:
    """Flat ids of the lattice nodes at either end of an edge whose ends differ in sign."""
    ids = np.arange(mean.size).reshape(mean.shape)
    flat, out = mean.ravel(), []
    for ax in range(mean.ndim):
        a = np.take(ids, range(mean.shape[ax] - 1), axis=ax).ravel()
        b = np.take(ids, range(1, mean.shape[ax]), axis=ax).ravel()
        s = (flat[a] < 0) != (flat[b] < 0)
        out += [a[s], b[s]]
    return np.unique(np.concatenate(out))


def errors_vs_exact(est: ShapeEstimator) -> tuple[dict, float]:
    """(level_set_error_m, candidate_var_rel_error, ...) against a dense exact solve, and
    that solve's time (ms)."""
    t0 = time.perf_counter()
    ref = DenseReference(est)
    nodes = crossing_nodes(est.lattice_mean())
    mu, g = ref.mean_grad(est._lattice[nodes])
    m = est.map_array()
    cand = m[m["kind"] == 1]
    C = np.column_stack([cand["x"], cand["y"], cand["z"]])[:, : est.dim]
    var = ref.variance(C)
    naive_ms = 1e3 * (time.perf_counter() - t0)
    level = np.abs(est.lattice_mean().ravel()[nodes] - mu) / np.linalg.norm(g, axis=1)
    rel = np.abs(cand["variance"] - var) / var
    return {"level_set_error_m": float(level.max()), "level_set_error_median_m": float(np.median(level)),
            "candidate_var_rel_error": float(rel.max()), "candidates": int(len(C))}, naive_ms


def local_case(dim: int, n: int, reps: int, seed: int) -> dict:
    """One scalable-path record (run in its own process)."""
    est = ShapeEstimator.from_params({"mode": f"{dim}d", "method": "local", "duplicate_distance_m": 0.0})
    M = int(np.prod(est.lattice_shape))
    pts, nrm = contacts_on_sphere(np.random.default_rng(seed), n + reps, dim)
    t0 = time.perf_counter()
    for i in range(n):
        est.add_observation(pts[i], nrm[i], 1)
    build_s = time.perf_counter() - t0
    times, cpu, maps, maps_cpu = [], [], [], []
    for i in range(n, n + reps):
        wall_s, cpu_s = _timed_contact(est, pts[i], nrm[i])
        times.append(wall_s)
        cpu.append(cpu_s)
        if i >= n + reps - 5:  # the map after each of the last 5 contacts
            t0, c0 = time.perf_counter(), time.process_time()
            est.map_array()
            maps.append(time.perf_counter() - t0)
            maps_cpu.append(time.process_time() - c0)
    rss = peak_rss_mb()
    err, naive_ms = errors_vs_exact(est)
    inc_ms = 1e3 * float(np.median(times))
    loc = est.local
    return {"dim": dim, "n": n, "M": M, "incremental_ms": round(inc_ms, 3), "naive_ms": round(naive_ms, 1),
            "ratio": round(naive_ms / inc_ms, 1), "normals": True, "method": "local",
            **{k: (round(v, 7) if isinstance(v, float) else v) for k, v in err.items()},
            "incremental_cpu_ms": round(1e3 * float(np.median(cpu)), 3),
            "incremental_max_ms": round(1e3 * max(times), 1),
            "map_ms": round(1e3 * float(np.median(maps)), 1), "map_cpu_ms": round(1e3 * float(np.median(maps_cpu)), 1),
            "build_s": round(build_s, 1), "rows": int(loc.n), "leaves": len(loc.leaves), "experts": loc.n_active,
            "anchors": loc.n_anchors, "band_nodes": int(loc.band_mask.sum()),
            "state_mb": round(loc.state_bytes() / 2**20, 1), "peak_rss_mb": round(rss, 1)}


def _in_process(fn, *args):
    """Run fn(*args) in a fresh spawned process (its own peak RSS) and return its result."""
    with mp.get_context("spawn").Pool(1) as pool:
        return pool.apply(fn, args)


def _exact_case(dim, ns, reps, naive_reps, normals, seed):
    return run(dim, ns, reps, naive_reps, normals, seed)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", metavar="FILE", help="also write the figures as a JSON list of records")
    ap.add_argument("--ns", type=int, nargs="+", default=[50, 200, 500], help="exact path: contact counts")
    ap.add_argument("--local-ns", type=int, nargs="*", default=[200, 1000, 2000],
                    help="scalable path: contact counts (with normals); none to skip")
    ap.add_argument("--dims", type=int, nargs="+", default=[2, 3], choices=[2, 3])
    ap.add_argument("--reps", type=int, default=5, help="exact: incremental contacts timed per n (median)")
    ap.add_argument("--local-reps", type=int, default=20, help="local: contacts timed per n (median)")
    ap.add_argument("--naive-reps", type=int, default=1, help="naive refits timed per n >= 200 (median)")
    ap.add_argument("--normals", action="store_true", help="exact path: contacts carry normals (1 + dim rows)")
    ap.add_argument("--no-exact", action="store_true", help="skip the exact-path records")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    records = []
    if not args.no_exact:
        for dim in args.dims:
            records += _in_process(_exact_case, dim, sorted(args.ns), args.reps, args.naive_reps, args.normals,
                                   args.seed)
    for dim in args.dims:
        for n in sorted(args.local_ns):
            r = _in_process(local_case, dim, n, args.local_reps, args.seed)
            records.append(r)
            print(f"local {dim}D  n={n:4d}  M={r['M']:7d}  normals=True   incremental {r['incremental_ms']:7.2f} ms "
                  f"(cpu {r['incremental_cpu_ms']:.2f}, max {r['incremental_max_ms']:.0f})   map {r['map_ms']:6.1f} ms   "
                  f"exact solve {r['naive_ms']:9.1f} ms   ratio {r['ratio']:7.1f}x   level set "
                  f"{1e3 * r['level_set_error_m']:.3f} mm   var rel {r['candidate_var_rel_error']:.4f}   "
                  f"state {r['state_mb']:.0f} MB   peak RSS {r['peak_rss_mb']:.0f} MB", flush=True)
    goal = [r for r in records if r["method"] == "exact" and r["dim"] == 3 and r["n"] == 200]
    if goal:
        r = goal[0]
        met = r["ratio"] >= GOAL_RATIO and r["incremental_ms"] < GOAL_MS
        print(f"goal (exact, 3D, n=200, M={r['M']}): ratio >= {GOAL_RATIO:.0f}x and < {GOAL_MS:.0f} ms: "
              f"{r['ratio']:.1f}x, {r['incremental_ms']:.1f} ms -> {'MET' if met else 'NOT MET'}")
    for (dim, n), ms in LOCAL_GOALS_MS.items():
        for r in (r for r in records if r["method"] == "local" and r["dim"] == dim and r["n"] == n):
            met = r["incremental_ms"] <= ms and r["level_set_error_m"] <= LEVEL_SET_GOAL_M
            print(f"goal (local, {dim}D, n={n}, normals): update <= {ms:.0f} ms and level set <= 0.5 mm: "
                  f"{r['incremental_ms']:.1f} ms (cpu {r['incremental_cpu_ms']:.1f}), "
                  f"{1e3 * r['level_set_error_m']:.3f} mm -> {'MET' if met else 'NOT MET'}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(records, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
