"""Planner benchmark: one decision in 2D (128²) and 3D (48³ shell), LMDP vs per-candidate solves vs Dijkstra.

    python -m tactile_planner.bench [--json FILE] [--repeat N] [--decision-ns N ...]

A decision = parse the map + free-space graph + travel costs to every
candidate + strategy + path (``TouchPlanner.plan``), median of ``--repeat``
runs (the minimum is printed too: the machine is shared and noisy), 200
candidates as the estimator publishes by default. "Per-candidate" solves the same first-exit problem once per candidate
(assemble + factorise/solve per candidate, as without the one-solve trick);
"per-candidate (shared factor)" reuses one factorisation (2D) — the most
favourable per-candidate baseline. All figures come from one run, so their
ratios are meaningful even on a loaded machine.

The whole decision at scale (records with ``"kind": "decision"``, ``--decision-ns``,
default 200, 1000, 2000 contacts with normals on a 5 cm circle / sphere, seeded): the
GPIS estimator (``method`` exact and/or local, ``--decision-methods``) holds n contacts;
then, ``--decision-reps`` times, one more contact is added (update_ms), the map is built
(map_ms, ``ShapeEstimator.map_array``) and the planner decides on it (plan_ms, tip outside
the object); decision_ms = their sum, medians. Both take their parameters as a run of the
mode does (package defaults, then ``explore_<mode>.yaml``: the 3D planner runs ``info_travel``
per second with the mean as clearance; the records name the strategy and clearance). Before
2026-12-05 they took the package defaults (3D: ``info_travel``, distance clearance), which
no 3D run uses; those figures in docs/benchmarks.md say so. The exact path is run only up
to ``--decision-exact-max-n`` contacts (its lattice state is O(n M): 3D with normals at
n = 200 already holds 0.7 GB), by default in 2D only (``--decision-exact-dims``). Each case
runs in its own process; peak_rss_mb is that process's peak resident memory.
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

from .planner import TouchPlanner  # noqa: E402
from .synthetic import sphere_map  # noqa: E402

CASES = (
    dict(dim=2, n=128, params={"mode": "2d"}, tip=(0.38, -0.12, 0.06)),
    dict(dim=3, n=48, params={"mode": "3d", "shell_m": 0.03}, tip=(0.45, -0.06, 0.14)),
)


def _median_ms(fn, repeat: int) -> tuple[float, float, object]:
    """Median and minimum wall time (ms) of ``repeat`` calls, and the last result."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(times)), float(np.min(times)), out


def per_candidate_costs(planner: TouchPlanner, map_array, tip, shared_factor: bool) -> np.ndarray:
    """Cost to each candidate from its own first-exit solve (reads z_b at the start node)."""
    import scipy.sparse.csgraph as csg

    from .graph import build_free_graph
    from .maps import parse_variance_map

    p = planner.params
    lat, cands = parse_variance_map(map_array)
    graph = build_free_graph(lat, p["margin_m"], p["shell_m"], p["min_tip_z_m"])
    normal = cands.normal / np.linalg.norm(cands.normal, axis=1)[:, None]
    pre = cands.xyz + (p["standoff_m"] + p["tip_radius_m"]) * normal
    if lat.dim == 2:
        pre[:, 2] = lat.plane_z_m
    tip = np.asarray(tip, float)
    start = graph.nearest_node(tip)
    tn, tl = graph.attach(pre, int(p["attach_reach"]))
    _, comp = csg.connected_components(graph.length_m, directed=False)
    reach = (tn >= 0) & (comp[np.maximum(tn, 0)] == comp[start])
    tn = np.where(reach, tn, -1)
    be = planner.backend
    rate = be.effective_rate(graph)
    out = np.full(len(tn), np.inf)
    solve = None
    for b in np.flatnonzero(reach):
        if solve is None or not shared_factor:
            mat, _ = be.system(graph, tn, rate)
            solve, _ = be._solver(mat, lat.dim)
        rhs = np.zeros(graph.n_nodes)
        rhs[tn[b]] = np.exp(-rate * tl[b])
        out[b] = -np.log(solve(rhs)[start])
    return out


def run(repeat: int = 5, n_candidates: int = 200) -> list[dict]:
    records = []
    for case in CASES:
        m = sphere_map(case["n"], case["dim"], n_candidates=n_candidates)
        tip = np.array(case["tip"])
        lm = TouchPlanner.from_params(dict(case["params"], backend="lmdp"), seed=0)
        dj = TouchPlanner.from_params(dict(case["params"], backend="dijkstra"), seed=0)
        lm.plan(m, tip)  # warm-up (imports, caches)
        lmdp_ms, lmdp_min_ms, res = _median_ms(lambda: lm.plan(m, tip), repeat)
        dijkstra_ms, dijkstra_min_ms, res_d = _median_ms(lambda: dj.plan(m, tip), repeat)
        t0 = time.perf_counter()
        per = per_candidate_costs(lm, m, tip, shared_factor=False)
        per_ms = (time.perf_counter() - t0) * 1e3
        t0 = time.perf_counter()
        per_shared = per_candidate_costs(lm, m, tip, shared_factor=True)
        per_shared_ms = (time.perf_counter() - t0) * 1e3
        ok = np.isfinite(per) & np.isfinite(res.travel_costs)
        rec = {
            "dim": case["dim"], "lattice": f"{case['n']}^{case['dim']}", "nodes": res.n_nodes,
            "candidates": res.n_candidates, "status": res.status,
            "solver": res.backend_info.get("solver"),
            "lmdp_ms": round(lmdp_ms, 2), "lmdp_min_ms": round(lmdp_min_ms, 2),
            "per_candidate_ms": round(per_ms, 1),
            "per_candidate_shared_factor_ms": round(per_shared_ms, 1),
            "dijkstra_ms": round(dijkstra_ms, 2), "dijkstra_min_ms": round(dijkstra_min_ms, 2),
            "ratio_vs_per_candidate": round(per_ms / lmdp_ms, 1),
            "ratio_vs_per_candidate_shared_factor": round(per_shared_ms / lmdp_ms, 1),
            "ratio_vs_dijkstra": round(lmdp_ms / dijkstra_ms, 2),
            "max_cost_diff_vs_per_candidate_nats": float(np.max(np.abs(per[ok] - res.travel_costs[ok]))),
            "same_choice_as_dijkstra": bool(res.index == res_d.index),
        }
        records.append(rec)
        goal = 20.0 if case["dim"] == 2 else 200.0
        print(f"{rec['lattice']:>6} {rec['nodes']:6d} nodes {rec['candidates']:3d} candidates | "
              f"lmdp {lmdp_ms:6.1f} ms (min {lmdp_min_ms:.1f}; goal < {goal:.0f}) | per-candidate {per_ms:8.1f} ms "
              f"(×{rec['ratio_vs_per_candidate']}; shared factor {per_shared_ms:.1f} ms, "
              f"×{rec['ratio_vs_per_candidate_shared_factor']}) | dijkstra {dijkstra_ms:6.1f} ms "
              f"(lmdp/dijkstra ×{rec['ratio_vs_dijkstra']}) | max |ΔC| {rec['max_cost_diff_vs_per_candidate_nats']:.1e} nats")
    return records


DECISION_GOALS_MS = {(3, 1000): 50.0, (2, 2000): 15.0}  # issue 14: update + map + plan


def mode_params(dim: int) -> tuple[dict, dict]:
    """The estimator's and the planner's parameters as a run of this mode gets them: each package's
    defaults, then ``tactile_bringup/config/explore_<mode>.yaml`` (3D: ``info_travel`` per second with
    the mean as clearance), each node's declared parameters only."""
    from tactile_common.params_file import node_params, package_config
    from tactile_gpis import estimator as gpis_estimator

    from . import planner as soc_planner

    mode_file = package_config("tactile_bringup", f"explore_{dim}d.yaml")
    out = []
    for package, filename, node, table in (
            ("tactile_gpis", "gpis_estimator.yaml", "gpis_estimator", gpis_estimator.PARAMETERS),
            ("tactile_planner", "soc_planner.yaml", "soc_planner", soc_planner.PARAMETERS)):
        params = node_params([package_config(package, filename), mode_file], node)
        out.append({k: v for k, v in params.items() if k in table})
    return out[0], out[1]


def decision_case(dim: int, n: int, method: str, reps: int, seed: int) -> dict:
    """Median update / map / plan times of the estimator + planner at n contacts (own process)."""
    from tactile_gpis.bench import contacts_on_sphere
    from tactile_gpis.estimator import ShapeEstimator

    gpis_params, planner_params = mode_params(dim)
    est = ShapeEstimator.from_params({**gpis_params, "method": method, "duplicate_distance_m": 0.0})
    # the benchmark's sphere floats 5 cm above the table (its contacts are all there is): the 3D
    # default would answer that with a search under it (support_gap_m) and probes at the feet of its
    # walls (foot_probe_gap_m), not a decision on the map's candidates
    planner = TouchPlanner.from_params({**planner_params, "support_gap_m": 0.0, "foot_probe_gap_m": 0.0}, seed=seed)
    pts, nrm = contacts_on_sphere(np.random.default_rng(seed), n + reps, dim)
    for i in range(n):
        est.add_observation(pts[i], nrm[i], 1)
    tip = np.array([0.38, -0.12, 0.06]) if dim == 2 else np.array([0.42, -0.08, 0.16])
    planner.plan(est.map_array(), tip)  # warm-up
    upd, mp_, pl, cpu = [], [], [], []
    parts_cpu: list[tuple[float, float, float]] = []  # update, map, plan (process CPU)
    status = ""
    for i in range(n, n + reps):
        c0 = time.process_time()
        t0 = time.perf_counter()
        ok, why = est.add_observation(pts[i], nrm[i], 1)
        t1, c1 = time.perf_counter(), time.process_time()
        m = est.map_array()
        t2, c2 = time.perf_counter(), time.process_time()
        res = planner.plan(m, tip)
        t3 = time.perf_counter()
        cpu.append(time.process_time() - c0)
        parts_cpu.append((c1 - c0, c2 - c1, time.process_time() - c2))
        if not ok:
            raise RuntimeError(why)
        upd.append(t1 - t0)
        mp_.append(t2 - t1)
        pl.append(t3 - t2)
        status = res.status
    med = lambda v: round(1e3 * float(np.median(v)), 2)  # noqa: E731
    return {"kind": "decision", "dim": dim, "n": n, "normals": True, "method": method,
            "strategy": planner.params["strategy"], "clearance": planner.params["clearance"],
            "active_method": est.active_method, "update_ms": med(upd), "map_ms": med(mp_), "plan_ms": med(pl),
            "decision_ms": med(np.array(upd) + np.array(mp_) + np.array(pl)), "decision_cpu_ms": med(cpu),
            **{f"{k}_cpu_ms": med(np.array(parts_cpu)[:, j]) for j, k in enumerate(("update", "map", "plan"))},
            "status": status, "peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)}


def run_decisions(ns: list[int], methods: list[str], reps: int, exact_max_n: int, exact_dims=(2,),
                  dims=(2, 3)) -> list[dict]:
    records = []
    for dim in dims:
        for n in ns:
            for method in methods:
                if method == "exact" and (n > exact_max_n or dim not in exact_dims):
                    continue
                with mp.get_context("spawn").Pool(1) as pool:
                    r = pool.apply(decision_case, (dim, n, method, reps, 0))
                records.append(r)
                print(f"decision {dim}D n={n:4d} {method:5s} | update {r['update_ms']:8.2f} ms | map "
                      f"{r['map_ms']:7.1f} ms | plan {r['plan_ms']:7.1f} ms | decision {r['decision_ms']:8.1f} ms "
                      f"(cpu {r['decision_cpu_ms']:.1f} = update {r['update_cpu_ms']:.1f} + map {r['map_cpu_ms']:.1f} "
                      f"+ plan {r['plan_cpu_ms']:.1f}) | {r['status']} | peak RSS {r['peak_rss_mb']:.0f} MB",
                      flush=True)
    for (dim, n), ms in DECISION_GOALS_MS.items():
        for r in (r for r in records if r["dim"] == dim and r["n"] == n and r["method"] == "local"):
            print(f"goal (decision, local, {dim}D, n={n}): <= {ms:.0f} ms: {r['decision_ms']:.1f} ms "
                  f"(cpu {r['decision_cpu_ms']:.1f}) -> {'MET' if r['decision_ms'] <= ms else 'NOT MET'}")
    return records


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="also write the records to this file")
    ap.add_argument("--repeat", type=int, default=5, help="decisions per timing (median and min)")
    ap.add_argument("--candidates", type=int, default=200,
                    help="candidates per map (gpis_estimator default: 200)")
    ap.add_argument("--decision-ns", type=int, nargs="*", default=[200, 1000, 2000],
                    help="whole decision (update + map + plan) at these contact counts; none to skip")
    ap.add_argument("--decision-methods", nargs="+", default=["exact", "local"], choices=["exact", "local"])
    ap.add_argument("--decision-reps", type=int, default=7, help="decisions per case (median)")
    ap.add_argument("--decision-exact-max-n", type=int, default=200, help="largest n run with the exact path")
    ap.add_argument("--decision-exact-dims", type=int, nargs="*", default=[2], choices=[2, 3],
                    help="dims run with the exact path (3D with normals: ~1.5 s per contact at n = 200)")
    args = ap.parse_args(argv)
    records = run(args.repeat, args.candidates)
    if args.decision_ns:
        records += run_decisions(sorted(args.decision_ns), args.decision_methods, args.decision_reps,
                                 args.decision_exact_max_n, tuple(args.decision_exact_dims))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(records, fh, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
