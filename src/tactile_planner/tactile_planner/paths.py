"""Shortcut smoothing of a lattice path without entering the safety margin (world frame, m)."""

from __future__ import annotations

import numpy as np

from .graph import FreeSpaceGraph


def shortcut(graph: FreeSpaceGraph, points_xyz: np.ndarray) -> np.ndarray:
    """Greedy string pulling: from each kept point jump to the farthest later point
    whose straight segment keeps μ ≥ margin (sampled at a quarter lattice step).

    The first and last points are kept; the result is a subsequence of the input,
    so a path that was free stays free.
    """
    pts = np.asarray(points_xyz, float)
    if len(pts) <= 2:
        return pts.copy()
    keep = [0]
    i = 0
    while i < len(pts) - 1:
        later = np.arange(i + 1, len(pts))
        ok = graph.segments_free(np.repeat(pts[i:i + 1], len(later), axis=0), pts[later])
        ok[0] = True  # consecutive points: a lattice edge (or the end segments)
        j = int(later[np.flatnonzero(ok)[-1]])
        keep.append(j)
        i = j
    return pts[keep]


def path_length_m(points_xyz: np.ndarray) -> float:
    """Polyline length (m)."""
    p = np.asarray(points_xyz, float)
    return float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1))) if len(p) > 1 else 0.0
