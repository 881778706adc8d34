"""Simulated taxel counts from the fingertip's penetration into an object (ROS-free).

Spring skin model. The finger surface is sampled densely (points s with
area A_s, fingertip frame). With the fingertip pose (p, R), each sample's
penetration is delta_s = max(0, -sdf(p + R s)) and its force
f_s = k delta_s A_s (k = ``stiffness_pa_per_m``, pressure per metre of
penetration). The elastic skin spreads each sample's force over the taxels
with a Gaussian of the distance |x_i - s| (std ``spread_m``), normalised per
sample so that the counts sum to the force:

    v_i = b_i + c * sum_s Kn(i, s) f_s + noise,   Kn(i, s) = K(i, s) / max(sum_j K(j, s), K_ref)

with c = ``counts_per_newton``, b_i the per-taxel baseline (fixed offsets
drawn once from the model's seed), and Gaussian noise of std
``noise_counts`` drawn from the caller's generator. Counts are rounded and
clipped to uint16.

Objects follow the interface of docs/architecture.md (``dim``, ``sdf``,
``gradient``); a 2D object sees the (x, y) columns of the world points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from tactile_driver.taxels import TaxelLayout


@dataclass(frozen=True)
class SensorModelConfig:
    """Parameters of the spring skin model (defaults match the driver's ``tactile_sensor.yaml``)."""

    stiffness_pa_per_m: float = 2.0e7
    spread_m: float = 0.0025
    counts_per_newton: float = 10000.0
    baseline_counts: float = 1000.0
    baseline_spread_counts: float = 50.0
    noise_counts: float = 2.0
    sample_spacing_m: float = 0.0005


class SensorModel:
    """Per-taxel counts of a fingertip at a pose next to an object."""

    def __init__(self, layout: TaxelLayout, config: SensorModelConfig = SensorModelConfig(), seed: int = 0) -> None:
        self.layout = layout
        self.config = config
        s, _, area = layout.surface_samples(config.sample_spacing_m, margin_m=2.5 * config.spread_m)
        self._samples_m = s
        self._area_m2 = area
        d2 = np.sum((layout.positions_m[:, None, :] - s[None, :, :]) ** 2, axis=2)
        k = np.exp(-0.5 * d2 / config.spread_m**2)
        col = k.sum(axis=0)
        k /= np.maximum(col, np.median(col))[None, :]
        self._kernel_t = np.ascontiguousarray(k.T)  # (N_samples, N_taxels): rows gathered per frame
        # Clusters of samples around each taxel, for a cheap Lipschitz pre-test of the SDF.
        owner = np.argmin(d2, axis=0)
        self._cluster_of = owner
        self._cluster_radius_m = np.zeros(layout.n_taxels)
        np.maximum.at(self._cluster_radius_m, owner, np.sqrt(d2[owner, np.arange(s.shape[0])]))
        #: Radius of the sphere around the tip centre that holds every sample.
        self.bounding_radius_m = float(np.linalg.norm(s, axis=1).max())
        # Samples that share (x, y) in the fingertip frame: one SDF value for a 2D object and a vertical finger.
        self._xy_unique, self._xy_group = np.unique(np.round(s[:, :2], 9), axis=0, return_inverse=True)
        self._xy_group = self._xy_group.reshape(-1)
        rng = np.random.default_rng(seed)
        self.baseline_counts = config.baseline_counts + config.baseline_spread_counts * rng.uniform(
            -1.0, 1.0, layout.n_taxels
        )

    def sample_forces_n(self, obj: Any, position_m: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Indices and forces (N) of the surface samples inside the object."""
        p = np.asarray(position_m, dtype=float)
        if world_sdf(obj, p[None, :])[0] > self.bounding_radius_m:  # sdf is 1-Lipschitz
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        R = np.asarray(rotation, dtype=float)
        # sdf(x) >= sdf(c) - |x - c|: a cluster whose centre is farther out than its radius is free.
        centres = p + self.layout.positions_m @ R.T
        near = world_sdf(obj, centres) < self._cluster_radius_m
        cand = np.nonzero(near[self._cluster_of])[0]
        if cand.size == 0:
            return cand, np.zeros(0)
        if getattr(obj, "dim", 3) == 2 and abs(R[2, 2]) > 1.0 - 1e-12:  # vertical finger over a prism
            groups, inverse = np.unique(self._xy_group[cand], return_inverse=True)
            depth = -np.asarray(obj.sdf(p[:2] + self._xy_unique[groups] @ R[:2, :2].T), dtype=float)[inverse.reshape(-1)]
        else:
            depth = -world_sdf(obj, p + self._samples_m[cand] @ R.T)
        inside = depth > 0
        idx = cand[inside]
        return idx, self.config.stiffness_pa_per_m * depth[inside] * self._area_m2[idx]

    def force_n(self, obj: Any, position_m: np.ndarray, rotation: np.ndarray = np.eye(3)) -> float:
        """Total spring force of the skin (N)."""
        return float(self.sample_forces_n(obj, position_m, rotation)[1].sum())

    def clean_counts(self, obj: Any, position_m: np.ndarray, rotation: np.ndarray = np.eye(3)) -> np.ndarray:
        """(N,) noise-free counts (float): baseline + contact response."""
        idx, f = self.sample_forces_n(obj, position_m, rotation)
        out = self.baseline_counts.copy()
        if idx.size:
            out += self.config.counts_per_newton * (f @ self._kernel_t[idx])
        return out

    def add_noise(self, clean: np.ndarray, rng: Optional[np.random.Generator]) -> np.ndarray:
        """(N,) uint16 counts: clean + Gaussian noise, rounded and clipped."""
        noisy = clean if rng is None else clean + rng.normal(0.0, self.config.noise_counts, clean.shape)
        return np.clip(np.rint(noisy), 0, 0xFFFF).astype(np.uint16)

    def frame(
        self, obj: Any, position_m: np.ndarray, rotation: np.ndarray = np.eye(3),
        rng: Optional[np.random.Generator] = None,
    ) -> np.ndarray:
        """(N,) uint16 counts of one sensor frame (no noise when ``rng`` is None)."""
        return self.add_noise(self.clean_counts(obj, position_m, rotation), rng)


def world_sdf(obj: Any, points_m: np.ndarray) -> np.ndarray:
    """Object SDF at (N, 3) world points (2D objects see x, y)."""
    if getattr(obj, "dim", 3) == 2:
        points_m = points_m[:, :2]
    return np.asarray(obj.sdf(points_m), dtype=float)
