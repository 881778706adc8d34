"""Samples of an object's zero level set by projecting near-surface lattice nodes."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from tactile_sim.sdf_object import SDFObject


def _lattice(lo: np.ndarray, hi: np.ndarray, h: float) -> np.ndarray:
    axes = [np.arange(a, b + 0.5 * h, h) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lo))


def project_to_surface(obj: "SDFObject", h: float, iterations: int = 6, tol_m: float = 1e-7) -> np.ndarray:
    """Points on obj's zero level set, about one per lattice cell of size h (world frame, (M, dim)).

    Coarse cells (≤ 8h) whose centre has |d| ≤ half the cell diagonal may hold
    surface (|∇d| ≤ 1); their h-sub-lattice nodes with |d| ≤ h·√dim/2 are
    projected with p ← p − d(p)·∇d(p) until |d| < tol_m (one step for an
    exact SDF); points that do not converge in ``iterations`` steps are dropped.
    """
    dim = obj.dim
    lo, hi = obj.bounds[0] - 2 * h, obj.bounds[1] + 2 * h
    # Coarse pass: cells of size H whose centre is within the half diagonal of the surface.
    coarse = max(h, min(8 * h, float(np.min(hi - lo)) / 8))
    factor = max(1, int(round(coarse / h)))
    coarse = factor * h
    centres = _lattice(lo, hi, coarse)
    near = centres[np.abs(obj.sdf(centres)) <= 0.5 * coarse * np.sqrt(dim) + 1e-12]
    # Fine pass: the sub-lattice of spacing h inside the kept coarse cells.
    sub = (np.arange(factor) - 0.5 * (factor - 1)) * h
    offsets = np.stack(np.meshgrid(*([sub] * dim), indexing="ij"), axis=-1).reshape(-1, dim)
    p = (near[:, None, :] + offsets[None]).reshape(-1, dim)
    d = obj.sdf(p)
    keep = np.abs(d) <= 0.5 * h * np.sqrt(dim)
    p, d = p[keep], d[keep]
    done: list[np.ndarray] = []
    for _ in range(iterations):  # one step is exact for an exact SDF; iterate only the rest
        p = p - d[:, None] * obj.gradient(p)
        d = obj.sdf(p)
        ok = np.abs(d) < tol_m
        done.append(p[ok])
        p, d = p[~ok], d[~ok]
        if len(p) == 0:
            break
    return np.concatenate(done)
