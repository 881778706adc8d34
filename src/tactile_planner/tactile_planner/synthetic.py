"""Synthetic variance maps from an analytic circle / sphere SDF (for tests and the benchmark).

World frame, metres. Layout exactly as the GPIS estimator publishes it
(``VARIANCE_MAP_DTYPE``: lattice nodes kind 0 in C order, then candidates kind 1).
"""

from __future__ import annotations

import numpy as np

from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, VARIANCE_MAP_DTYPE

WORKSPACE_2D = ((0.35, 0.65), (-0.15, 0.15))
WORKSPACE_3D = ((0.35, 0.65), (-0.15, 0.15), (0.0, 0.22))


def sphere_map(n: int, dim: int, center=(0.5, 0.0, 0.06), radius_m: float = 0.05,
               n_candidates: int = 64, plane_z_m: float = 0.06, seed: int = 0,
               workspace=None) -> np.ndarray:
    """Map of a circle (2D, at plane_z_m) or sphere (3D): mean = exact SDF.

    Lattice variance = 1e-4·(1 + sin²(3·angle)); candidate variances are seeded
    random in [1e-5, 1e-3] m². Candidates are evenly spread on the surface
    (3D: a Fibonacci sphere, kept above z = 0.02 m).
    """
    rng = np.random.default_rng(seed)
    ws = workspace or (WORKSPACE_2D if dim == 2 else WORKSPACE_3D)
    axes = [np.linspace(lo, hi, n) for lo, hi in ws]
    mesh = np.meshgrid(*axes, indexing="ij")
    pts = np.stack([m.ravel() for m in mesh], axis=1)
    c = np.asarray(center, float)[:dim]
    sdf = np.linalg.norm(pts - c, axis=1) - radius_m
    lat = np.zeros(len(pts), VARIANCE_MAP_DTYPE)
    lat["x"], lat["y"] = pts[:, 0], pts[:, 1]
    lat["z"] = pts[:, 2] if dim == 3 else plane_z_m
    lat["mean"] = sdf
    ang = np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0])
    lat["variance"] = 1e-4 * (1 + np.sin(3 * ang) ** 2)
    lat["kind"] = KIND_LATTICE
    if dim == 2:
        t = np.linspace(0, 2 * np.pi, n_candidates, endpoint=False)
        nrm = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], axis=1)
    else:
        k = np.arange(4 * n_candidates) + 0.5
        phi = np.arccos(1 - 2 * k / len(k))
        th = np.pi * (1 + 5**0.5) * k
        nrm = np.stack([np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)], axis=1)
        nrm = nrm[center[2] + radius_m * nrm[:, 2] > 0.02][:n_candidates]
    cen = np.array([center[0], center[1], plane_z_m if dim == 2 else center[2]])
    cand = np.zeros(len(nrm), VARIANCE_MAP_DTYPE)
    p = cen + radius_m * nrm
    cand["x"], cand["y"], cand["z"] = p[:, 0], p[:, 1], p[:, 2]
    cand["normal_x"], cand["normal_y"], cand["normal_z"] = nrm[:, 0], nrm[:, 1], nrm[:, 2]
    cand["variance"] = 10 ** rng.uniform(-5, -3, len(nrm))
    cand["kind"] = KIND_CANDIDATE
    return np.concatenate([lat, cand])
