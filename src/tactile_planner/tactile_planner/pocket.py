"""Pre-touch points in a pocket of the estimate: joined to the graph along the approach axis.

The graph keeps the tip centre ``margin_m`` from the estimated surface. Where the
estimate closes a concavity too far (a slot estimated narrower or shallower than
it is, the surface the estimate gets most wrong and so the most uncertain), a
candidate's pre-touch point lies inside that margin: it was unreachable ("no free
pre-touch point", "last segment not free"), and the planner touched known
surface instead (docs/exploration.md). A finger in a pocket needs less than the
path margin: its own radius plus a small gap. So such a pre-touch point is entered
along its approach axis, from the first point at most ``max_back_m`` further out
along the candidate's normal that joins the graph at the margin; the entry segment
must keep the tip centre ``min_clearance_m`` (tip radius + gap) from the estimated
surface. If the estimate is right the finger fits; if the pocket is narrower than
estimated the commander stops on the contact and keeps it (a path contact is an
observation). World frame, metres.
"""

from __future__ import annotations

import numpy as np

from .graph import FreeSpaceGraph


def pocket_entries(graph: FreeSpaceGraph, pretouch_xyz: np.ndarray, normal_xyz: np.ndarray, max_back_m: float,
                   min_clearance_m: float, reach: int = 2,
                   allowed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For (M, 3) pre-touch points and unit normals: the entry point ``pretouch + k h n`` (h = the
    lattice step, smallest k ≥ 1 with k h ≤ ``max_back_m``) that attaches to a free node within
    ``reach`` cells (among the ``allowed`` nodes, (N,) bool, if given: the tip's component) with a
    margin-free last segment, and whose segment to the pre-touch point keeps
    clearance ≥ ``min_clearance_m``. Returns entry (M, 3), its node (M,) and the node-to-entry
    length (M,) in m; node −1 (entry NaN, length inf) where there is none."""
    pre = np.asarray(pretouch_xyz, float).reshape(-1, 3)
    n = np.asarray(normal_xyz, float).reshape(-1, 3)
    m = len(pre)
    entry = np.full((m, 3), np.nan)
    node = np.full(m, -1, dtype=np.int64)
    length = np.full(m, np.inf)
    h = float(np.min(graph.lattice.spacing_m))
    if m == 0 or not max_back_m > 0 or graph.n_nodes == 0:
        return entry, node, length
    # the pre-touch point itself must leave the finger room
    todo = graph.clearance_m(pre) >= min_clearance_m - 1e-9
    for k in range(1, int(np.floor(max_back_m / h + 1e-9)) + 1):
        idx = np.flatnonzero(todo)
        if not len(idx):
            break
        cand = pre[idx] + k * h * n[idx]
        nd, dist = graph.attach(cand, reach, allowed)
        ok = nd >= 0
        if ok.any():
            ok[ok] = graph.segments_free(graph.xyz[nd[ok]], cand[ok])
        if ok.any():  # the entry segment: the finger's own clearance, sampled at a quarter step
            samples = np.linspace(0.0, 1.0, 4 * k + 1)
            seg = pre[idx[ok], None, :] + samples[None, :, None] * (cand[ok] - pre[idx[ok]])[:, None, :]
            room = graph.clearance_m(seg.reshape(-1, 3)).reshape(len(seg), -1).min(axis=1) >= min_clearance_m - 1e-9
            take = np.flatnonzero(ok)[room]
            entry[idx[take]], node[idx[take]], length[idx[take]] = cand[take], nd[take], dist[take]
            todo[idx[take]] = False
    return entry, node, length


def closer_pretouch(graph: FreeSpaceGraph, target_xyz: np.ndarray, normal_xyz: np.ndarray, offset_m: float,
                    min_offset_m: float, min_clearance_m: float) -> np.ndarray:
    """Pre-touch points ``target + d n`` ((M, 3)) with the largest d ≤ ``offset_m`` (the full standoff +
    tip radius), down to ``min_offset_m``, at which the tip centre keeps ``min_clearance_m`` from the
    estimated surface (d sampled at a quarter lattice step); where no such d exists, the full one.

    A side wall of a slot narrower than the full offset plus ``min_clearance_m`` has no room at the full
    standoff (the opposite wall is too close), but may have it nearer the wall. The commander's approach is the same
    length from wherever the pre-touch point is, so the skin may go that much further beyond the
    estimated surface: the depth is a bound, and the approach stops on contact."""
    t = np.asarray(target_xyz, float).reshape(-1, 3)
    n = np.asarray(normal_xyz, float).reshape(-1, 3)
    out = t + offset_m * n
    if len(t) == 0 or not min_offset_m < offset_m:
        return out
    h = float(np.min(graph.lattice.spacing_m)) / 4.0
    d = np.arange(offset_m, min_offset_m - 1e-12, -h)  # (K,), largest first
    pts = t[:, None, :] + d[None, :, None] * n[:, None, :]  # (M, K, 3)
    room = graph.clearance_m(pts.reshape(-1, 3)).reshape(len(t), len(d)) >= min_clearance_m - 1e-9
    has = room.any(axis=1)
    first = np.argmax(room, axis=1)
    out[has] = pts[np.flatnonzero(has), first[has]]
    return out
