"""Parse the GPIS variance map (``VARIANCE_MAP_DTYPE``) into a regular lattice plus candidates.

World frame, metres. The lattice nodes (kind 0) come first in C order of a
regular lattice (x slowest; 2D: x then y, all with z = plane height; 3D: x, y,
z); the lattice is rebuilt from the unique coordinates of each axis and the
order is checked. Candidates (kind 1) follow with mean, variance and unit
outward normal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, normals, xyz


class MapError(ValueError):
    """A variance map that cannot be planned on, with the reason."""


@dataclass(frozen=True)
class MapLattice:
    """Regular lattice of the estimator (world frame).

    Attributes:
        axes: per lattice axis the sorted node coordinates (m); 2 axes (x, y) in 2D, 3 in 3D.
        mean_m: GP mean of f on the lattice, shape = lattice shape (m, < 0 inside).
        variance_m2: GP variance of f on the lattice (m²).
        plane_z_m: the plane height in 2D (None in 3D).
    """

    axes: tuple
    mean_m: np.ndarray
    variance_m2: np.ndarray
    plane_z_m: float | None

    @property
    def dim(self) -> int:
        return len(self.axes)

    @property
    def shape(self) -> tuple:
        return tuple(len(a) for a in self.axes)

    @property
    def origin(self) -> np.ndarray:
        return np.array([a[0] for a in self.axes])

    @property
    def spacing_m(self) -> np.ndarray:
        return np.array([a[1] - a[0] for a in self.axes])

    def grid_xyz(self) -> np.ndarray:
        """(prod(shape), 3) world coordinates of every lattice node, C order."""
        mesh = np.meshgrid(*self.axes, indexing="ij")
        cols = [m.ravel() for m in mesh]
        if self.dim == 2:
            cols.append(np.full(cols[0].shape, self.plane_z_m))
        return np.stack(cols, axis=1)


@dataclass(frozen=True)
class Candidates:
    """Touch candidates on the estimated surface (world frame)."""

    xyz: np.ndarray  # (M, 3) m
    normal: np.ndarray  # (M, 3) unit outward normal
    mean_m: np.ndarray  # (M,)
    variance_m2: np.ndarray  # (M,)

    def __len__(self) -> int:
        return int(self.xyz.shape[0])


def _evenly_spaced(axis: np.ndarray) -> bool:
    """An axis of fewer than two values, or strictly increasing with equal steps (rtol 1e-6)."""
    if len(axis) < 2:
        return True
    steps = np.diff(axis)
    return bool(steps[0] > 0 and np.allclose(steps, steps[0], rtol=1e-6, atol=1e-9))


def _axis(values: np.ndarray, name: str) -> np.ndarray:
    u = np.unique(values)
    if not _evenly_spaced(u):
        raise MapError(f"lattice {name} coordinates are not evenly spaced")
    return u


def _in_c_order(p: np.ndarray, axes) -> bool:
    """Every node (N, 3) at its place on the lattice of ``axes`` in C order (to 1e-9 m): node
    (i, j, k) holds (axes[0][i], axes[1][j], axes[2][k]), compared by broadcasting, not a meshgrid."""
    shape = tuple(len(a) for a in axes)
    if int(np.prod(shape)) != len(p):
        return False
    q = p[:, : len(axes)].reshape(*shape, len(axes))
    for k, a in enumerate(axes):
        along = tuple(slice(None) if j == k else None for j in range(len(axes)))
        if not np.max(np.abs(q[..., k] - np.asarray(a)[along]), initial=0.0) <= 1e-9:  # NaN: not in place
            return False
    return True


def _c_order_axes(p: np.ndarray) -> list[np.ndarray] | None:
    """The x, y, z axes of nodes (N, 3) that form a C-order lattice (x slowest, z fastest), read
    off the rows in O(N) rather than sorted out; None when the rows are not one, or an axis is
    not increasing and evenly spaced (the caller's sorted path then says what is wrong)."""
    block, axes = 1, [None, None, None]
    for k in (2, 1, 0):  # fastest first: an axis's values repeat after its length
        seq = p[::block, k]
        again = np.flatnonzero(seq[1:] == seq[0])
        n = int(again[0]) + 1 if len(again) and k > 0 else len(seq)
        axes[k], block = seq[:n].copy(), block * n
    if block != len(p) or not all(_evenly_spaced(a) for a in axes):
        return None
    return axes if _in_c_order(p, axes) else None


def parse_variance_map(map_array: np.ndarray) -> tuple[MapLattice, Candidates]:
    """Split a variance map into its lattice and its candidates.

    Raises:
        MapError: wrong dtype, no lattice, lattice not regular / not in C order,
            non-finite values.
    """
    arr = np.asarray(map_array)
    needed = ("x", "y", "z", "mean", "variance", "normal_x", "normal_y", "normal_z", "kind")
    if arr.dtype.names is None or any(n not in arr.dtype.names for n in needed):
        raise MapError(f"map must be a structured array with fields {needed}")
    kind = arr["kind"]
    n_lat = int(np.count_nonzero(kind == KIND_LATTICE))
    if n_lat == 0:
        raise MapError("map has no lattice nodes (kind 0)")
    if not np.all(kind[:n_lat] == KIND_LATTICE):
        raise MapError("lattice nodes (kind 0) must come before the candidates (kind 1)")
    if np.any((kind[n_lat:] != KIND_CANDIDATE)):
        raise MapError("unknown point kind after the lattice (expected 1 = candidate)")
    lat = arr[:n_lat]
    p = xyz(lat)
    if not (np.isfinite(p).all() and np.isfinite(lat["mean"]).all() and np.isfinite(lat["variance"]).all()):
        raise MapError("lattice holds non-finite coordinates, mean or variance")
    ax = _c_order_axes(p)
    in_order = ax is not None
    if not in_order:  # not a C-order lattice: find the axes by sorting, to say what is wrong
        ax = [_axis(p[:, k], "xyz"[k]) for k in range(3)]
    if len(ax[2]) == 1:  # 2D: every node at the plane height
        axes, plane_z = (ax[0], ax[1]), float(ax[2][0])
    else:
        axes, plane_z = tuple(ax), None
    shape = tuple(len(a) for a in axes)
    if any(s < 2 for s in shape):
        raise MapError(f"lattice must have at least 2 nodes per axis, got shape {shape}")
    if int(np.prod(shape)) != n_lat:
        raise MapError(f"{n_lat} lattice nodes do not form a full lattice of shape {shape}")
    if not in_order and not _in_c_order(p, axes):
        raise MapError("lattice nodes are not in C order (x slowest, then y, then z)")
    lattice = MapLattice(
        axes=axes,
        mean_m=lat["mean"].astype(np.float64).reshape(shape),
        variance_m2=np.maximum(lat["variance"].astype(np.float64), 0.0).reshape(shape),
        plane_z_m=plane_z,
    )
    cand = arr[n_lat:]
    cands = Candidates(
        xyz=xyz(cand),
        normal=normals(cand),
        mean_m=cand["mean"].astype(np.float64),
        variance_m2=cand["variance"].astype(np.float64),
    )
    return lattice, cands
